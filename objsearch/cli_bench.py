"""``objsearch bench``: the experiments (paper tables, held-out homes, the results document)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from objsearch import cli_types as t
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.outdir import claim

#: What bench paper and bench homes write into --out (an earlier run's files are replaced).
PAPER_OUTPUTS = ("paper_trials.parquet", "paper_trials.csv", "summary.json", "tables.txt", "logs")
HOMES_OUTPUTS = (
    "homes_trials.parquet",
    "homes_trials.csv",
    "summary.json",
    "tables.txt",
    "learning_*",  # the learning curves, as PNG, SVG and PDF
)


def _strategies(names: list[str] | None, default: str) -> list[str]:
    """``--strategies``: names, or one of the words ``paper`` (sdp,rvp,wpl) and ``all``."""
    from objsearch.experiments.strategies import PAPER_STRATEGIES, STRATEGIES

    names = names or [default]
    if names == ["all"]:
        return list(STRATEGIES)
    if names == ["paper"]:
        return list(PAPER_STRATEGIES)
    return names


def _targets(args: argparse.Namespace) -> list[str]:
    """``--targets`` (default: all eight), each checked against the eight."""
    from objsearch.experiments.runner import TARGETS

    targets = args.targets or list(TARGETS)
    unknown = [name for name in targets if name not in TARGETS]
    if unknown:
        raise ObjsearchError(
            f"--targets: {', '.join(unknown)} not among the eight targets ({', '.join(TARGETS)})"
        )
    return list(targets)


def cmd_bench_paper(args: argparse.Namespace) -> int:
    from objsearch.experiments.paper import figures, render, run_paper

    targets = _targets(args)
    out = Path(args.out)
    with claim(out, command="bench paper", owns=PAPER_OUTPUTS, replace_needs_force=False):
        summary = run_paper(
            out,
            strategies=_strategies(args.strategies, "all"),
            sdp_seeds=args.sdp_seeds,
            workers=t.workers(args),
            progress=not args.no_progress and args.format != "json",
            targets=targets,
            scenes=args.scenes,
            keep_logs=args.keep_logs,
            prior=args.prior,
            camera=args.camera,
        )
    if args.format == "json":
        # The figures the text prints, not only the headline metrics (summary.json: everything).
        print(json.dumps({**_headline(summary), **figures(summary)}, indent=2))
    else:
        print(render(summary))
        print(
            f"\n{summary['searches']} searches in {summary['elapsed_s']} s; results in {args.out}"
        )
        print(_unseeable(summary))
    return 0


def cmd_bench_homes(args: argparse.Namespace) -> int:
    from objsearch.experiments.homes import render, run_homes

    out = Path(args.out)
    with claim(out, command="bench homes", owns=HOMES_OUTPUTS, replace_needs_force=False):
        summary = run_homes(
            out,
            homes=args.homes,
            strategies=_strategies(args.strategies, "all"),
            seeds=args.seeds,
            scenes=args.scenes_per_schedule,
            workers=t.workers(args),
            progress=not args.no_progress and args.format != "json",
            schedules=args.schedules,
            starts_per_search=args.starts_per_scene,
            camera=args.camera,
            inspection=args.inspection,
            perception=t.perception_params(args),
            localisation=t.localisation_params(args),
            new_map_day=args.new_map_day,
            new_map_frame=args.new_map_frame,
            prior=args.prior,
        )
    if args.format == "json":
        print(json.dumps(_headline(summary), indent=2))
    else:
        print(render(summary))
        print(
            f"\n{summary['searches']} searches in {summary['elapsed_s']} s; results in {args.out}"
        )
        print(_unseeable(summary))
    return 0


def cmd_bench_table1(args: argparse.Namespace) -> int:
    from objsearch.experiments.table1_sets import OUTPUTS, render, run_table1_sets

    targets = _targets(args)
    out = Path(args.out)
    with claim(out, command="bench table1", owns=OUTPUTS, replace_needs_force=False):
        summary = run_table1_sets(
            out,
            source=Path(args.source),
            sets=args.sets,
            seed=args.seed,
            workers=t.workers(args),
            targets=targets,
            progress=not args.no_progress,
            prior=args.prior,
            camera=args.camera,
        )
    print(render(summary))
    print(_unseeable(summary))
    print(f"\nresults in {args.out} (summary.md, summary.json, table1_sets.csv)")
    return 0


def cmd_bench_belief(args: argparse.Namespace) -> int:
    from objsearch.experiments.report_belief import report, select_models
    from objsearch.experiments.report_data import check_data_folders

    folders = [Path(d) for d in args.homes]
    data = [Path(d) for d in args.data or []]
    check_data_folders(data)
    missing = [str(d) for d in folders if not (d / "homes_trials.parquet").is_file()]
    if missing:
        raise ObjsearchError(
            f"not a bench homes output (no homes_trials.parquet): {', '.join(missing)}"
        )
    perception, localisation = select_models(folders, args.perception, args.localisation)
    perfect = [Path(d) for d in args.perfect or []]
    missing = [str(d) for d in perfect if not (d / "homes_trials.parquet").is_file()]
    if missing:
        raise ObjsearchError(
            f"--perfect: not a bench homes output (no homes_trials.parquet): {', '.join(missing)}"
        )
    if perfect:
        select_models(perfect, "perfect", localisation)
    baseline = _baseline(args, folders, (perception, localisation))
    text = f"perception {perception}, localisation {localisation}; " + report(
        folders,
        Path(args.out),
        progress=lambda kinds: t.progress(
            kinds, "bench belief", " schedule kinds", total=len(kinds), enabled=not args.no_progress
        ),
        perfect=perfect,
        baseline=baseline,
        data=data,
    )
    print(text)
    (Path(args.out) / "belief.md").write_text(text + "\n", encoding="utf-8")
    print(f"\nwrote {Path(args.out) / 'belief.md'}")
    return 0


def _baseline(
    args: argparse.Namespace, folders: list[Path], models: tuple[str, str]
) -> tuple[str, list[Path]] | None:
    """bench belief's ``--baseline DIR`` and its ``--baseline-label``: the label (by default
    what the baseline's summary.json says differs: perception, localisation, the new-map day or
    its frame)
    and the folders; None without ``--baseline``."""
    from objsearch.experiments.report_belief import select_models
    from objsearch.experiments.report_newmap import new_map_day, new_map_frame

    baseline = [Path(d) for d in args.baseline or []]
    if not baseline:
        if args.baseline_label is not None:
            raise ObjsearchError("--baseline-label names the --baseline runs: give --baseline DIR")
        return None
    missing = [str(d) for d in baseline if not (d / "homes_trials.parquet").is_file()]
    if missing:
        raise ObjsearchError(
            f"--baseline: not a bench homes output (no homes_trials.parquet): {', '.join(missing)}"
        )
    try:
        theirs = select_models(baseline)
    except ObjsearchError as e:
        raise ObjsearchError(f"--baseline: {e}") from None
    if args.baseline_label is not None:
        return args.baseline_label, baseline
    differs = [
        f"{what} {value}"
        for what, ours, value in zip(("perception", "localisation"), models, theirs, strict=True)
        if ours != value
    ]
    days = {new_map_day(d) for d in folders}, {new_map_day(d) for d in baseline}
    if days[0] != days[1] and len(days[1]) == 1:
        (day,) = days[1]
        differs.append("no new map" if day is None else f"new map on day {day}")
    frames = {new_map_frame(d) for d in folders}, {new_map_frame(d) for d in baseline}
    if frames[0] != frames[1] and len(frames[1]) == 1:
        (frame,) = frames[1]
        differs.append(f"new map's frame {frame}")
    if not differs:
        raise ObjsearchError(
            "--baseline: its runs have the same perception, localisation, new-map day and frame "
            "as the runs reported; name what differs with --baseline-label"
        )
    return ", ".join(differs), baseline


def cmd_bench_routine_ceiling(args: argparse.Namespace) -> int:
    from objsearch.experiments.routine_ceiling import ceiling_text

    folders = [Path(d) for d in args.runs]
    missing = [str(d) for d in folders if not (d / "homes_trials.parquet").is_file()]
    if missing:
        raise ObjsearchError(
            f"not a bench homes output (no homes_trials.parquet): {', '.join(missing)}"
        )
    text = ceiling_text(folders, args.kind)
    if text is None:
        raise ObjsearchError(f"{', '.join(args.runs)}: no {args.kind}-<seed> searches")
    print(text)
    return 0


#: Where bench report looks for a bench paper output when --paper is not given.
DEFAULT_PAPER_RUN = "out/bench-paper"


def cmd_bench_report(args: argparse.Namespace) -> int:
    from objsearch.experiments.report import REPORT_STAGES, ReportInputs, write_report

    homes = [Path(d) for d in args.evaluation or ()]
    heldout = None if args.heldout is None else [Path(d) for d in args.heldout]
    paper: Path | None = Path(args.paper or DEFAULT_PAPER_RUN)
    if args.paper is None and not (Path(DEFAULT_PAPER_RUN) / "summary.json").is_file():
        paper = None  # the paper home's sections say how to make one
        if not (homes or heldout or args.table1 or args.rearr):
            raise ObjsearchError(
                f"nothing to report: no bench paper output in {DEFAULT_PAPER_RUN}, and no "
                "--paper, --evaluation, --heldout, --table1 or --rearr given"
            )
    given = [paper] if paper is not None else []
    missing = [str(d) for d in (*given, *homes) if not (d / "summary.json").is_file()]
    if args.rearr:
        from objsearch.experiments.report_rearr import RESULTS_FILE, write_rearr_report

        target = Path(args.rearr_out) if args.rearr_out else Path(args.out).parent / RESULTS_FILE
        print(f"wrote {write_rearr_report(Path(args.rearr), target)}")
        # Without another bench output only the rearrangement page is written.
        if missing or (paper is None and not (homes or heldout or args.table1)):
            why = f"no bench summary in {', '.join(missing)}" if missing else "no other output"
            print(f"kept {args.out}: {why}")
            return 0
    shared = {d.resolve() for d in homes} & {d.resolve() for d in heldout or ()}
    if shared:
        raise ObjsearchError(
            f"--heldout {', '.join(sorted(map(str, shared)))} is also an --evaluation folder: "
            "held-out homes are reported apart, from a bench homes run of their own"
        )
    inputs = ReportInputs(
        paper=paper,
        homes=tuple(homes),
        table1=None if args.table1 is None else tuple(Path(d) for d in args.table1),
        heldout=None if heldout is None else tuple(heldout),
        paper_geometric=None if args.paper_geometric is None else Path(args.paper_geometric),
    )
    out = Path(args.out)
    img = Path(args.img) if args.img else out.parent / "img"
    with t.progress_bar(
        "bench report", " stages", total=len(REPORT_STAGES), enabled=not args.no_progress
    ) as bar:
        started: list[str] = []

        def stage(name: str) -> None:  # the bar counts the stages done
            if started:
                bar.update()
            started.append(name)
            bar.set_postfix_str(name)

        path = write_report(inputs, out, img, progress=stage)
    print(f"wrote {path}")
    if args.html:
        from objsearch.experiments.report_html import write_results_html

        print(f"wrote {write_results_html(path)}")
    return 0


def _unseeable(summary: dict[str, Any]) -> str:
    """One line per placement no viewpoint can see, left out of its scene's searches."""
    left_out = summary["unseeable"]
    lines = [
        f"camera {summary['camera']}; {len(left_out)} placement(s) no viewpoint can see, left out "
        "of their scenes' searches (summary.json: unseeable)" + (":" if left_out else "")
    ]
    lines += [
        f"  {u['home']} {u['placements']} scene {u['scene']}: {u['cls']} {u['instance_id']} "
        f"(best {u['best_mask_px']} px)"
        for u in left_out
    ]
    return "\n".join(lines)


def _headline(summary: dict[str, Any]) -> dict[str, Any]:
    keys = ("command", "camera", "elapsed_s", "searches", "unseeable", "strategies", "files")
    return {k: _rounded(summary[k]) for k in keys if k in summary}


#: Decimals of a metric in a printed summary (summary.json keeps every digit).
SUMMARY_DECIMALS = 4


def _rounded(value: Any) -> Any:
    """``value`` with every float in it rounded to :data:`SUMMARY_DECIMALS`."""
    if isinstance(value, float):
        return round(value, SUMMARY_DECIMALS)
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_rounded(v) for v in value]
    return value


def _prior_option(p: argparse.ArgumentParser) -> None:
    from objsearch.agent.session import DEFAULT_PRIOR, PRIOR_FILES

    p.add_argument(
        "--prior",
        type=t.text,
        choices=tuple(PRIOR_FILES),
        default=DEFAULT_PRIOR,
        help="the reading of Eq. 2 the scene graph is seeded with (docs/paper-readings.md) "
        f"({DEFAULT_PRIOR})",
    )


def _model_choices(p: argparse.ArgumentParser) -> None:
    """bench belief's ``--perception`` and ``--localisation``: which simulated detector and
    localisation the outputs it reads must have been run with."""
    from objsearch.agent.detector_model import PRESETS as DETECTORS
    from objsearch.sim.localisation import PRESETS as LOCALISERS

    p.add_argument(
        "--perception",
        type=t.text,
        choices=DETECTORS,
        help="the simulated detector the outputs were run with (their summary.json); an output "
        "run with another is refused (default: any one, the same for all)",
    )
    p.add_argument(
        "--localisation",
        type=t.text,
        choices=LOCALISERS,
        help="the simulated localisation the outputs were run with, likewise",
    )


def _common(p: argparse.ArgumentParser, out: str) -> None:
    p.add_argument("--out", default=out, type=t.dir_path, help=f"output folder ({out})")
    p.add_argument(
        "--strategies",
        type=t.name_list,
        **t.LIST,
        help="comma-separated names, 'paper' (sdp,rvp,wpl) or 'all' (default: all)",
    )
    p.add_argument(
        "--workers",
        type=t.int_range(0, t.MAX_WORKERS),
        default=0,
        help=f"processes, at most {t.MAX_WORKERS} and one per job (0, the default: min(2, cores))",
    )
    t.format_option(p, "print a JSON summary per strategy")
    t.progress_option(p)
    t.camera_option(p)


def _add_paper(bsub: Any) -> None:
    paper = bsub.add_parser("paper", help="Table I and the long-term experiment on the paper home")
    _common(paper, "out/bench-paper")
    paper.add_argument(
        "--sdp-seeds",
        type=t.int_range(1, 1000),
        default=20,
        help="seeds for SDP's random rooms, 1-1000 (20)",
    )
    paper.add_argument(
        "--targets", type=t.name_list, **t.LIST, help="comma-separated subset of the eight targets"
    )
    paper.add_argument(
        "--scenes",
        type=t.SCENES,
        **t.LIST,
        help=f"comma-separated subset of Table II's scenes (1-{t.MAX_SCENE})",
    )
    paper.add_argument("--keep-logs", action="store_true", help="keep long-term event logs")
    paper.defer(_prior_option)
    paper.set_defaults(func=cmd_bench_paper)


def _add_homes(bsub: Any) -> None:
    homes = bsub.add_parser("homes", help="every strategy on the held-out homes")
    _common(homes, "out/bench-homes")
    homes.add_argument(
        "--homes",
        type=t.name_list,
        **t.LIST,
        help="comma-separated home names (default: all but 'paper')",
    )
    homes.add_argument(
        "--seeds",
        type=t.int_range(1, 1000),
        default=1,
        help="schedules per home, seeds 0..N-1, N 1-1000 (1)",
    )
    # A count, not a list of scenes as record's and bench paper's --scenes (which it once was
    # spelled as: kept as a deprecated alias).
    t.renamed(
        homes,
        "--scenes",
        homes.add_argument(
            "--scenes-per-schedule",
            type=t.int_range(1, t.MAX_SEEDED_SCENES),
            help=f"scenes per schedule, 1-{t.MAX_SEEDED_SCENES} (each kind's own: 10, habit 30, routine and homer 84); "
            "stats and rearr schedules can be drawn longer than 10",
        ),
    )
    homes.add_argument(
        "--schedules",
        default="stats",
        type=t.name_list,
        **t.LIST,
        help="comma-separated schedule kinds, each run with seeds 0..N-1: stats (drawn from "
        "AI2-THOR placement statistics), rearr (real rearrangement episodes; iTHOR homes only), "
        "habit (objects with a usual place and alternates, 30 scenes), moved, routine (routines "
        "of our design, 84 scenes), homer (routines measured in the HOMER households, 84 scenes) "
        "(stats)",
    )
    t.renamed(
        homes,
        "--starts",
        homes.add_argument(
            "--starts-per-scene",
            type=t.int_range(1, 100),
            help="search each target from this many start points per scene, drawn per (seed, scene, "
            "target), 1-100 (default: from every start point, as the paper)",
        ),
    )
    homes.add_argument(
        "--inspection",
        type=t.text,
        choices=("single", "cover"),
        default="single",
        help="single: each static from its nearest viewpoint N_s (the paper); cover: statics "
        "longer than 1.5 m also from the viewpoints nearest each 1.5 m stretch (single)",
    )
    t.perception_option(homes)
    t.localisation_option(homes)
    homes.add_argument(
        "--new-map-day",
        type=t.int_range(1),
        metavar="N",
        help="from scene N on the robot runs in a new map (a new session with the next map id; "
        "where flags answers resting on the old map) (never)",
    )
    homes.add_argument(
        "--new-map-frame",
        type=t.text,
        choices=("same", "moved"),
        default="same",
        help="the new map's frame: the old map's, or moved by a rigid transform drawn from the "
        "seed, as a fresh SLAM map's (the agent registers it by its statics) (same)",
    )
    homes.defer(_prior_option)
    homes.set_defaults(func=cmd_bench_homes)


def _add_table1(bsub: Any) -> None:
    table1 = bsub.add_parser(
        "table1",
        help="Table I over a seeded sample of FloorPlan sets that satisfy the paper's removal rule "
        "(docs/results-table1.md)",
    )
    table1.add_argument(
        "--out",
        default="out/bench-table1",
        type=t.dir_path,
        help="output folder (out/bench-table1)",
    )
    table1.add_argument(
        "--source",
        default="../shared/data",
        type=t.existing_dir,
        help="the shared raw data the homes are built from (../shared/data)",
    )
    table1.add_argument(
        "--sets", type=t.int_range(1, 100000), default=100, help="sampled FloorPlan sets (100)"
    )
    table1.add_argument(
        "--seed", type=t.int_range(0, 2**31 - 1), default=1, help="seed of the sample order (1)"
    )
    table1.add_argument(
        "--targets", type=t.name_list, **t.LIST, help="comma-separated subset of the eight targets"
    )
    table1.add_argument(
        "--workers",
        type=t.int_range(0, t.MAX_WORKERS),
        default=0,
        help=f"processes, at most {t.MAX_WORKERS} (0, the default: min(2, cores))",
    )
    table1.defer(_prior_option)
    t.progress_option(table1)
    t.camera_option(table1)
    table1.set_defaults(func=cmd_bench_table1)


def _add_belief(bsub: Any) -> None:
    belief = bsub.add_parser(
        "belief",
        help="the belief's figures from bench homes outputs (docs/results-belief.md)",
        description="First search of the day against the distribution oracle with bootstrap "
        "CIs over runs, paired differences, what a moved habit costs day by day, calibration of "
        "the belief's forecasts, failures, and learning curves with CI bands (PNG and SVG).",
    )
    belief.add_argument(
        "homes",
        nargs="+",
        type=t.existing_dir,
        metavar="DIR",
        help="bench homes output folder(s), read as one",
    )
    belief.add_argument(
        "--out",
        default="out/belief-report",
        type=t.dir_path,
        help="folder for belief.md and the curves (out/belief-report)",
    )
    belief.add_argument(
        "--perfect",
        action="append",
        type=t.existing_dir,
        metavar="DIR",
        help="a bench homes output of the same runs with --perception perfect (repeatable): the "
        "protocol's headline is also given ÷ the same strategy there",
    )
    belief.add_argument(
        "--baseline",
        action="append",
        type=t.existing_dir,
        metavar="DIR",
        help="a bench homes output of the same runs but for one factor, such as --localisation "
        "perfect (repeatable): the protocol's headline is also given ÷ the same strategy there, "
        "in a column named by --baseline-label",
    )
    belief.add_argument(
        "--baseline-label",
        type=t.text,
        metavar="LABEL",
        help="what the --baseline runs differ in, the column's name (default: the perception, "
        "localisation or new-map day their summary.json says differs)",
    )
    belief.add_argument(
        "--data",
        action="append",
        type=t.existing_dir,
        metavar="DIR",
        help="a data folder to read the outputs' homes from (repeatable), for an output whose "
        "summary.json names no folder holding them; each output's homes are read from the "
        "folder it records, else the first --data folder holding them, else $OBJSEARCH_DATA or "
        "the bundled data",
    )
    belief.defer(_model_choices)
    t.progress_option(belief)
    belief.set_defaults(func=cmd_bench_belief)


def _add_ceiling(bsub: Any) -> None:
    ceiling = bsub.add_parser(
        "routine-ceiling",
        help="why a memory of the hour gains what it gains on routine schedules "
        "(docs/results-routine.md)",
        description="From bench homes outputs of routine or homer schedules: how much knowing "
        "the hour tells (the chance the likeliest place or room holds the object, time-blind "
        "against the slot's own distribution) and where the references' paths go (the part no "
        "memory can shorten; the first search of each scene against later ones).",
    )
    ceiling.add_argument(
        "runs",
        nargs="+",
        type=t.existing_dir,
        metavar="DIR",
        help="bench homes output folder(s) with routine-<seed> or homer-<seed> searches",
    )
    ceiling.add_argument(
        "--kind",
        # sim.schedule_names.ROUTINE_KINDS, spelled out: importing it would load the simulator at
        # every start-up (tests/experiments/test_routine_ceiling.py holds the two equal)
        choices=("routine", "homer"),
        default="routine",
        help="the schedule kind (routine)",
    )
    ceiling.set_defaults(func=cmd_bench_routine_ceiling)


def _add_report(bsub: Any) -> None:
    report = bsub.add_parser(
        "report",
        help="write the results page (docs/results.md's generator) from bench outputs",
        description="Write the results page and its plots from bench outputs. Each section whose "
        "input is not given says which command produces it. Writes under out/report/ unless "
        "--out says otherwise (the committed page is docs/results.md: pass --out "
        "docs/results.md --img docs/img to regenerate it).",
    )
    report.add_argument(
        "--paper",
        type=t.dir_path,
        metavar="DIR",
        help=f"bench paper output folder (default: {DEFAULT_PAPER_RUN} if it holds one; without "
        "one the paper home's sections say how to make it)",
    )
    # --homes names homes (bench homes --homes ithor-02,…); a folder of bench homes output here
    # is --evaluation (--homes, its old spelling, still works with a note).
    t.renamed(
        report,
        "--homes",
        report.add_argument(
            "--evaluation",
            action="append",
            type=t.dir_path,
            metavar="DIR",
            help="a bench homes output on the homes to evaluate on (the Homes section); repeat "
            "to report several runs (e.g. one per schedule kind) as one (default: none, the "
            "section says how to make one)",
        ),
    )
    report.add_argument(
        "--out",
        metavar="FILE",
        default="out/report/results.md",
        type=t.file_path,
        help="the results page to write (out/report/results.md)",
    )
    report.add_argument(
        "--img",
        metavar="DIR",
        type=t.dir_path,
        help="folder for the PNG plots (default: img/ beside --out)",
    )
    report.add_argument(
        "--table1",
        metavar="DIR",
        action="append",
        type=t.existing_dir,
        help="a bench table1 output: the Table I distribution section (left out without it); "
        "repeat with one run per --prior to compare the readings of Eq. 2",
    )
    report.add_argument(
        "--heldout",
        metavar="DIR",
        action="append",
        type=t.existing_dir,
        help="a bench homes output on held-out homes, reported in a section of its own "
        "(repeatable like --evaluation)",
    )
    report.add_argument(
        "--paper-geometric",
        metavar="DIR",
        type=t.existing_dir,
        help="a bench paper output with the other camera: both cameras' Table I/II and their "
        "difference",
    )
    report.add_argument(
        "--rearr",
        metavar="DIR",
        type=t.existing_dir,
        help="a bench homes output with --schedules rearr[,stats]: also write the "
        "rearrangement page (the results page only if the --paper output exists)",
    )
    report.add_argument(
        "--rearr-out",
        metavar="FILE",
        type=t.file_path,
        help="where the rearrangement page goes (default: results-rearrangement.md beside --out)",
    )
    report.add_argument(
        "--html",
        action="store_true",
        help="also write index.html beside --out: the same page, self-contained (sortable "
        "tables, inline SVG figures)",
    )
    t.progress_option(report)
    report.set_defaults(func=cmd_bench_report)


def register(sub: Any) -> None:
    bench = sub.add_parser("bench", help="experiments: the paper's tables, held-out homes, report")
    bsub = bench.add_subparsers(dest="bench_command", required=True, metavar="SUBCOMMAND")
    _add_paper(bsub)
    _add_homes(bsub)
    from objsearch.cli_sensitivity import register as register_sensitivity

    register_sensitivity(bsub)
    _add_table1(bsub)
    _add_belief(bsub)
    _add_ceiling(bsub)
    from objsearch.cli_bench_external import add_dhs, add_stot

    add_dhs(bsub)
    add_stot(bsub)
    _add_report(bsub)
