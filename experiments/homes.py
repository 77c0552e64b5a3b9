"""``objsearch bench homes``: every strategy on homes we did not tune on, with seeded schedules (one
per seed and kind): ``stats`` drawn from AI2-THOR placement statistics, ``rearr`` taken from real
AI2-THOR rearrangement episodes (iTHOR-based homes only)."""

from __future__ import annotations

import json
import math
import os
import re
import statistics
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from objsearch.agent.errors import ObjsearchError
from objsearch.agent.home import available_homes, load_home
from objsearch.agent.session import DEFAULT_PRIOR
from objsearch.experiments.learning import (
    learning_summary,
    paired_differences,
    paired_json,
    plot_curves,
    render_learning,
    render_paired,
)
from objsearch.experiments.metrics import mean_std, summarise
from objsearch.experiments.runner import (
    TARGETS,
    Job,
    Row,
    command_line,
    inspection_suffix,
    run_jobs,
    unseeable,
    write_rows,
)
from objsearch.experiments.strategies import STRATEGIES, full_strategy_name, split_strategy
from objsearch.sim.rearr_schedule import homes_with_rearrangement, why_no_rearrangement
from objsearch.sim.schedule_names import SEEDED_KINDS, UnknownScheduleError
from objsearch.sim.world import DEFAULT_CAMERA


def heldout_homes() -> tuple[str, ...]:
    """Every home but the paper's (which the paper's method, and our choices, were seen on)."""
    return tuple(h for h in available_homes() if h != "paper")


def family(home: str) -> str:
    return "procthor" if home.startswith("procthor") else "ithor"


#: The reference a strategy is measured against under a modelled detector: the whole-home
#: distribution oracle, seeing with the same detector and confirming by the same rule (it runs
#: the same search loop), inspecting as the strategy does (issue 45).
REFERENCE = "dist-oracle-global"


def reference_of(strategy: str) -> str:
    """The reference run beside ``strategy`` under a modelled detector (:data:`REFERENCE`, with
    the strategy's own inspection)."""
    return full_strategy_name(REFERENCE, split_strategy(strategy)[1])


def homes_jobs(
    homes: Sequence[str],
    strategies: Sequence[str],
    seeds: int,
    *,
    scenes: int | None = None,
    targets: Sequence[str] = TARGETS,
    schedules: Sequence[str] = ("stats",),
    starts_per_search: int | None = None,
    camera: str = DEFAULT_CAMERA,
    inspection: str = "single",
    perception: str | None = None,
    prior: str = DEFAULT_PRIOR,
) -> list[Job]:
    known = set(available_homes())
    unknown = [h for h in homes if h not in known]
    if unknown:
        raise ObjsearchError(
            f"unknown home(s) {', '.join(unknown)}; available: {', '.join(sorted(known))}"
        )
    # ``--inspection cover`` is every strategy named NAME+cover; a name may also say so itself.
    strategies = [
        full_strategy_name(registered.name, "cover" if inspection == "cover" else own)
        for registered, own in map(split_strategy, strategies)
    ]
    bad = [k for k in schedules if k not in SEEDED_KINDS]
    if bad or not schedules:
        raise UnknownScheduleError(
            f"unknown schedule kind(s) {', '.join(bad) or '(none given)'}; "
            f"expected a comma-separated subset of {', '.join(SEEDED_KINDS)}"
        )
    if "rearr" in schedules:
        have = set(homes_with_rearrangement())
        missing = [h for h in homes if h not in have]
        if missing:
            why = "; ".join(why_no_rearrangement(load_home(h)) for h in missing)
            raise ObjsearchError(
                f"home(s) {', '.join(missing)} have no rearrangement data: {why}; homes with "
                f"data: {', '.join(sorted(have)) or 'none'}; use --schedules stats for the others"
            )
    if perception is not None:
        # Path ÷ a reference that sees with the same detector: add it, once per inspection.
        strategies = list(dict.fromkeys([*strategies, *map(reference_of, strategies)]))
    scene_ids = tuple(range(1, scenes + 1)) if scenes else None
    jobs = []
    for home in homes:
        for kind in schedules:
            for seed in range(seeds):
                spec = f"{kind}-{seed}"
                for name in strategies:
                    jobs.append(
                        Job(
                            "homes",
                            home,
                            spec,
                            name,
                            "all",
                            seed,
                            tuple(targets),
                            scene_ids,
                            starts_per_search=starts_per_search,
                            camera=camera,
                            perception=perception,
                            prior=prior,
                        )
                    )
                for wpl in (n for n in strategies if split_strategy(n)[0].name == "wpl"):
                    jobs.append(
                        Job(
                            "homes",
                            home,
                            spec,
                            wpl,
                            "none",
                            seed,
                            tuple(targets),
                            scene_ids,
                            starts_per_search=starts_per_search,
                            camera=camera,
                            perception=perception,
                            prior=prior,
                        )
                    )
    return jobs


def schedule_kind(spec: str) -> str:
    return spec.partition("-")[0]


def _key(r: Row) -> str:
    return r.strategy if r.update_mode == "all" else f"{r.strategy}/{r.update_mode}"


def _with_spread(rows: Sequence[Row]) -> dict[str, Any]:
    """Metrics of ``rows`` and their spread: over (home, schedule) runs, each one mean path length,
    and over seeds, each the mean of its runs."""
    lengths: dict[tuple[str, str], list[float]] = {}
    seed_of: dict[tuple[str, str], int] = {}
    for r in rows:
        lengths.setdefault((r.home, r.placements), []).append(r.path_length)
        seed_of[(r.home, r.placements)] = r.seed
    per_run = {hs: statistics.fmean(v) for hs, v in sorted(lengths.items())}
    per_seed = [
        statistics.fmean(v for hs, v in per_run.items() if seed_of[hs] == s)
        for s in sorted(set(seed_of.values()))
    ]
    _, sd = mean_std(list(per_run.values()))
    _, sd_seed = mean_std(per_seed)
    return {
        **summarise(rows),
        "runs": len(per_run),
        "std_over_runs": sd,
        "std_over_seeds": sd_seed,
    }


def data_build_commands(data: Path) -> list[str]:
    """The ``objsearch data build`` commands a data folder's PROVENANCE.md records, each with
    ``--out`` naming the folder: what rebuilds it from a clean clone."""
    provenance = data / "PROVENANCE.md"
    if not provenance.is_file():
        return []
    found = re.findall(r"objsearch data build [^`\n]*", provenance.read_text(encoding="utf-8"))
    commands = dict.fromkeys(c.strip() for c in found)  # in order, once each
    return [c if " --out " in c else f"{c} --out {data}" for c in commands]


#: bench homes options renamed after runs recorded their command line (the old spellings still
#: parse, with a note): a recorded command is shown with today's names, so a reader who copies it
#: gets no notes. tests/test_cli_conventions.py keeps it equal to the CLI's deprecated aliases.
RENAMED_OPTIONS: dict[str, str] = {
    "--scenes": "--scenes-per-schedule",
    "--starts": "--starts-per-scene",
}


def todays_spelling(command: str) -> str:
    """A recorded bench homes command line with its renamed options spelled as today."""
    return re.sub(r"(?<=\s)(--[a-z-]+)(?=\s)", lambda m: RENAMED_OPTIONS.get(m[1], m[1]), command)


def homes_command(summary: dict[str, Any], folder: Path) -> str:
    """The full command that produced a bench homes output: as recorded (today's option names),
    or rebuilt from the summary's fields for runs from before summaries recorded it. A run with no
    camera recorded predates the occluding camera, so it used the geometric one."""
    camera = str(summary.get("camera", "geometric"))
    command = summary.get("command")
    if command is not None:
        command = todays_spelling(str(command))
    else:
        strategies = [k for k in summary.get("strategies", {}) if "/" not in k]
        scenes, starts = summary.get("scenes"), summary.get("starts_per_search")
        command = command_line(
            "objsearch bench homes",
            {
                "out": folder,
                "homes": summary.get("homes"),
                "schedules": summary.get("schedules"),
                "seeds": len(summary["seeds"]) if "seeds" in summary else None,
                "scenes_per_schedule": scenes if isinstance(scenes, int) else None,
                "strategies": strategies or None,
                "starts_per_scene": starts if isinstance(starts, int) else None,
                "workers": summary.get("workers"),
            },
        )
    if camera != DEFAULT_CAMERA and "--camera" not in command:
        command += f" --camera {camera}"
    return str(command)


def perception_options(perception: dict[str, Any] | None) -> dict[str, object]:
    """The bench homes options that name a perception model (none for a perfect one): the
    preset, each parameter the preset does not give, and the confirmation model when it is not
    the preset's (a run spec that names none confirmed by ``score``, the runs before the option),
    the draws when they are not ``place`` (a run spec that names none drew by view), and the
    reports when they are not ``evidence`` (a run spec that names none counted them as misses),
    the relook when it is not the preset's (a run spec that names none did not relook), and the
    stop misses when they are not the preset's (a run spec that names none pooled them)."""
    if not perception:
        return {}
    from objsearch.agent.detector_model import OVERRIDES, PerceptionModel, preset

    run = PerceptionModel.from_params(perception)
    base = preset(run.preset)
    changed: dict[str, object] = {
        k: getattr(run, k)
        for k in OVERRIDES
        if getattr(run, k) != getattr(base, k)
        and not (k == "fp_recurrence" and run.confirmation == "score")
    }
    if run.confirmation != base.confirmation:
        changed["confirmation"] = run.confirmation
    if run.draws != base.draws:
        changed["draws"] = run.draws
    if run.reports != base.reports:
        changed["reports"] = run.reports
    if run.relook != base.relook:
        changed["relook"] = run.relook
    if run.stop_misses != base.stop_misses:
        changed["stop_misses"] = run.stop_misses
    return {"perception": run.preset, **changed}


def _search_key(r: Row) -> tuple[str, str, int, int, str, str]:
    return (r.home, r.placements, r.seed, r.scene, r.target, r.start)


def reference_ratio(rows: Sequence[Row], reference: Sequence[Row]) -> float | None:
    """Σ path ÷ Σ the reference's path over the searches both made (same home, schedule, seed,
    scene, target and start); None when they share none."""
    theirs = {_search_key(r): r.path_length for r in reference}
    shared = [(r.path_length, theirs[_search_key(r)]) for r in rows if _search_key(r) in theirs]
    denominator = math.fsum(b for _, b in shared)
    if not shared or denominator <= 0:
        return None
    return math.fsum(a for a, _ in shared) / denominator


def homes_summary(rows: Sequence[Row]) -> dict[str, Any]:
    keys = list(dict.fromkeys(_key(r) for r in rows))
    out: dict[str, Any] = {"overall": {}, "by_schedule": {}, "by_family": {}, "by_home": {}}
    for k in keys:
        mine = [r for r in rows if _key(r) == k]
        out["overall"][k] = _with_spread(mine)
        out["overall"][k]["false_found_rate"] = sum(r.false_found for r in mine) / len(mine)
        ref = reference_of(k.partition("/")[0])
        if ref != k and any(_key(r) == ref for r in rows):
            reference = [r for r in rows if _key(r) == ref]
            out["overall"][k]["reference"] = ref
            out["overall"][k]["reference_ratio"] = reference_ratio(mine, reference)
            for fam in sorted({family(r.home) for r in mine}):
                out.setdefault("reference_by_family", {}).setdefault(fam, {})[k] = reference_ratio(
                    [r for r in mine if family(r.home) == fam],
                    [r for r in reference if family(r.home) == fam],
                )
        for kind in sorted({schedule_kind(r.placements) for r in mine}):
            out["by_schedule"].setdefault(kind, {})[k] = _with_spread(
                [r for r in mine if schedule_kind(r.placements) == kind]
            )
        for fam in sorted({family(r.home) for r in mine}):
            out["by_family"].setdefault(fam, {})[k] = summarise(
                r for r in mine if family(r.home) == fam
            )
        for home in sorted({r.home for r in mine}):
            out["by_home"].setdefault(home, {})[k] = summarise(r for r in mine if r.home == home)
    # Wins: in how many (home, schedule) runs each strategy beats the paper's WPL, inspecting as
    # it does (wpl+cover for a cover run: --inspection cover names every strategy so).
    lengths: dict[tuple[str, str, str], list[float]] = {}
    for r in rows:
        lengths.setdefault((_key(r), r.home, r.placements), []).append(r.path_length)
    run_mean = {key: statistics.fmean(v) for key, v in lengths.items()}
    for k in keys:
        wpl = "wpl" + inspection_suffix(k.partition("/")[0])
        for kind in [None, *out["by_schedule"]]:
            wins = total = 0
            for (key, home, spec), base in run_mean.items():
                if key != wpl or (kind and schedule_kind(spec) != kind):
                    continue
                own = run_mean.get((k, home, spec))
                if own is not None:
                    total += 1
                    wins += own < base - 1e-9
            target = out["overall"] if kind is None else out["by_schedule"][kind]
            if k in target:
                target[k]["runs_better_than_wpl"] = f"{wins}/{total}"
    # Per home and schedule kind: the paired view (same home, same strategy, other schedules).
    by_hs: dict[str, dict[str, dict[str, list[float]]]] = {}
    for (k, home, spec), mean in sorted(run_mean.items()):
        by_hs.setdefault(home, {}).setdefault(schedule_kind(spec), {}).setdefault(k, []).append(
            mean
        )
    out["by_home_schedule"] = {
        home: {
            kind: {k: statistics.fmean(v) for k, v in per.items()} for kind, per in kinds.items()
        }
        for home, kinds in by_hs.items()
    }
    return out


def render(summary: dict[str, Any]) -> str:
    starts = summary.get("starts_per_search")
    homes, seeds = summary.get("homes") or [], summary.get("seeds") or []
    # A run with a modelled detector says which, and how often a false sighting ended a search.
    noisy = summary.get("perception", {}).get("preset", "perfect") != "perfect" or any(
        s.get("false_found_rate") for s in summary["overall"].values()
    )
    perception = f", perception {summary['perception']['preset']}" if noisy else ""
    lines = [
        f"{len(homes)} home(s) × {len(seeds)} seed(s): every target in every scene "
        f"from {f'{starts} start point(s)' if starts else 'every start point'}; "
        f"full path (m), camera {summary.get('camera', '?')}{perception}"
    ]
    referenced = any("reference_ratio" in s for s in summary["overall"].values())
    lines.append(
        f"{'strategy':20}{'n':>7}{'path m':>9}{'±runs':>7}{'success':>9}{'SPL':>7}{'oracle×':>9}{'< wpl':>8}"
        + (f"{'false found':>13}" if noisy else "")
        + (f"{'÷ ref':>8}" if referenced else "")
    )
    for k, s in summary["overall"].items():
        ratio = s.get("reference_ratio")
        lines.append(
            f"{k:20}{s['n']:7d}{s['mean_path_length']:9.2f}{s['std_over_runs']:7.2f}{s['success_rate']:9.1%}"
            f"{s['spl']:7.3f}{s['oracle_ratio']:9.2f}{s['runs_better_than_wpl']:>8}"
            + (f"{s.get('false_found_rate', 0.0):13.2%}" if noisy else "")
            + ((f"{ratio:8.2f}" if ratio is not None else f"{'–':>8}") if referenced else "")
        )
    if referenced:
        refs = sorted({s["reference"] for s in summary["overall"].values() if "reference" in s})
        lines.append(
            f"÷ ref: path ÷ the path of {', '.join(refs)} on the same searches (the distribution "
            "oracle, seeing with the same detector and confirming by the same rule)"
        )
    if len(summary.get("by_schedule", {})) > 1:
        for kind, per in summary["by_schedule"].items():
            lines.append(f"\n{kind} schedules: mean path length (m) ±runs / SPL")
            for k, s in per.items():
                lines.append(
                    f"  {k:20}{s['mean_path_length']:8.2f}{s['std_over_runs']:7.2f}"
                    f"{s['spl']:8.3f}  success {s['success_rate']:.1%}"
                )
    for fam, per in summary["by_family"].items():
        lines.append(f"\n{fam} homes: mean path length (m) / SPL")
        by_ref = summary.get("reference_by_family", {}).get(fam, {})
        for k, s in per.items():
            ratio = by_ref.get(k)
            lines.append(
                f"  {k:20}{s['mean_path_length']:8.2f}{s['spl']:8.3f}  success {s['success_rate']:.1%}"
                + (f"  ÷ ref {ratio:.2f}" if ratio is not None else "")
            )
    return "\n".join(lines)


def run_homes(
    out: Path,
    *,
    homes: Sequence[str] | None,
    strategies: Sequence[str] | None,
    seeds: int = 1,
    scenes: int | None = None,
    workers: int = 2,
    progress: bool = True,
    schedules: Sequence[str] = ("stats",),
    starts_per_search: int | None = None,
    camera: str = DEFAULT_CAMERA,
    inspection: str = "single",
    perception: dict[str, Any] | None = None,
    localisation: dict[str, Any] | None = None,
    new_map_day: int | None = None,
    new_map_frame: str = "same",
    prior: str = DEFAULT_PRIOR,
) -> dict[str, Any]:
    if new_map_frame != "same" and new_map_day is None:
        raise ObjsearchError("a new map's frame moves only with a new map: give its day")
    out.mkdir(parents=True, exist_ok=True)
    homes = list(homes) if homes else list(heldout_homes())
    strategies = list(strategies) if strategies else list(STRATEGIES)
    jobs = homes_jobs(
        homes,
        strategies,
        seeds,
        scenes=scenes,
        schedules=schedules,
        starts_per_search=starts_per_search,
        camera=camera,
        inspection=inspection,
        perception=json.dumps(perception, sort_keys=True) if perception else None,
        prior=prior,
    )
    if localisation or new_map_day is not None:
        # The robot's pose error and its change of map (sim/localisation.py, agent/maps.py).
        loc = json.dumps(localisation, sort_keys=True) if localisation else None
        jobs = [
            replace(j, localisation=loc, new_map_day=new_map_day, new_map_frame=new_map_frame)
            for j in jobs
        ]
    started = time.perf_counter()
    rows = run_jobs(jobs, workers=workers, progress=progress, label="bench homes")
    elapsed = time.perf_counter() - started
    parquet, csv = write_rows(rows, out, "homes_trials")
    data = os.environ.get("OBJSEARCH_DATA") or None
    command = command_line(
        "objsearch bench homes",
        {
            "out": out,
            "homes": homes,
            "schedules": schedules,
            "seeds": seeds,
            "scenes_per_schedule": scenes,
            "strategies": strategies,
            "starts_per_scene": starts_per_search,
            "camera": None if camera == DEFAULT_CAMERA else camera,
            "inspection": None if inspection == "single" else inspection,
            **perception_options(perception),
            "localisation": localisation["preset"] if localisation else None,
            "new_map_day": new_map_day,
            "new_map_frame": None if new_map_frame == "same" else new_map_frame,
            "prior": None if prior == DEFAULT_PRIOR else prior,
            "workers": workers,
        },
    )
    summary = {
        "command": f"OBJSEARCH_DATA={data} {command}" if data else command,
        # How the data folder the homes came from was built, so the run can be repeated.
        "data_build": data_build_commands(Path(data)) if data else [],
        "camera": camera,
        "perception": perception or {"preset": "perfect"},
        "localisation": localisation or {"preset": "perfect"},
        "new_map_day": new_map_day,
        # Absent: the new map keeps the old frame (every output before frames could move).
        **({"new_map_frame": new_map_frame} if new_map_frame != "same" else {}),
        "inspection": inspection,
        # Every search of this bench starts from this prior (``--prior``); dist-oracle alone
        # also reads the schedule's own distribution (a reference, never a default).
        "prior": prior,
        "homes": homes,
        "seeds": list(range(seeds)),
        "schedules": list(schedules),
        "scenes": scenes or "each kind's own (10; habit 30)",
        "starts_per_search": starts_per_search or "every start",
        "workers": workers,
        "elapsed_s": round(elapsed, 1),
        "searches": len(rows),
        "unseeable": unseeable(jobs),
        **homes_summary(rows),
        "files": {"parquet": parquet.name, "csv": csv.name},
    }
    _finish(summary, rows, out)
    return summary


def _finish(summary: dict[str, Any], rows: Sequence[Row], out: Path) -> None:
    """Add the strategies' means, the learning curves, the pairs against wpl and the plots to
    ``summary``, and write it (summary.json) and its tables (tables.txt) to ``out``."""
    keys = ("mean_path_length", "success_rate", "spl", "oracle_ratio")
    summary["strategies"] = {k: {m: s[m] for m in keys} for k, s in summary["overall"].items()}
    learning = learning_summary(rows)
    summary["learning"] = learning
    paired = paired_differences(rows)  # empty without a wpl of a strategy's own inspection
    summary["paired_vs_wpl"] = paired_json(paired)
    summary["plots"] = [p.name for p in plot_curves(rows, out)]
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    tables = render(summary) + "\n" + render_learning(learning)
    tables += "\n" + render_paired(paired) + "\n"
    (out / "tables.txt").write_text(tables, encoding="utf-8")
