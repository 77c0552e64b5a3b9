"""The ``objsearch`` command line."""

from __future__ import annotations

import argparse
import importlib
import io
import json
import logging
import os
import shutil
import sys
import tempfile
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from objsearch import cli_types as t
from objsearch.agent.errors import ObjsearchError

if TYPE_CHECKING:
    from objsearch.agent.results import SearchResult
    from objsearch.agent.session import HomeContext
    from objsearch.sim.placements import Placement

EXIT_USAGE = 2
#: Each room type has 25 iTHOR scenes, one of them the paper's: at most 24 held-out homes.
HELDOUT_ITHOR_MAX = 24


def _fail(message: str) -> int:
    print(f"objsearch: error: {message}", file=sys.stderr)
    return EXIT_USAGE


# -- data -------------------------------------------------------------------------------------


def cmd_data_build(args: argparse.Namespace) -> int:
    from objsearch.agent.datapaths import build_output_dir
    from objsearch.pipeline.build import build_data, parse_home_arg, parse_procthor_arg
    from objsearch.pipeline.errors import BuildError
    from objsearch.pipeline.findings import FindingsError

    try:
        homes = dict(parse_home_arg(spec) for spec in args.ithor) if args.ithor else None
        houses = dict(parse_procthor_arg(spec) for spec in args.procthor) if args.procthor else None
        report = build_data(
            Path(args.source),
            build_output_dir(args.out),
            homes=homes,
            procthor=houses,
            heldout_ithor=args.heldout_ithor or (),
            accept=args.accept or (),
            # A line per home built: a log of the build, in a pipe too (--no-progress: none).
            progress=None
            if args.format == "json" or args.no_progress
            else lambda line: print(line, file=sys.stderr),
        )
    except FindingsError as exc:
        if args.format == "json":
            refused = [f.to_json() for f in exc.findings]
            print(json.dumps({"written": [], "refused": refused}, indent=2))
        return _fail(str(exc))
    except BuildError as exc:
        return _fail(str(exc))
    if args.format == "json":
        doc = {
            "written": [str(p) for p in report.files],
            "notes": list(report.notes),
            "accepted": [{**f.to_json(), "reason": why} for f, why in report.findings],
        }
        print(json.dumps(doc, indent=2))
        return 0
    for note in report.notes:
        print(note)
    for finding, why in report.findings:
        print(f"accepted {finding.text()} ({why})")
    for path in report.files:
        print(f"wrote {path}")
    return 0


# -- search -----------------------------------------------------------------------------------


def run_spec(args: argparse.Namespace, home: Any, **extra: Any) -> Any:
    """The run spec the search options name (--strategy, --alpha, --seed, --update-mode)."""
    from objsearch.agent.scene_graph import UpdateMode
    from objsearch.agent.strategies import RunSpec

    return RunSpec.of(
        home.name,
        home.digest,
        args.strategy,
        seed=args.seed,
        alpha=args.alpha,
        update_mode=UpdateMode(getattr(args, "update_mode", "all")),
        params=_sim_params(args),
        **extra,
    )


def _sim_params(args: argparse.Namespace) -> dict[str, Any]:
    """The simulated robot's sensors a run records: its camera and, unless perfect, its detector
    and its localisation."""
    perception = t.perception_params(args)
    localisation = t.localisation_params(args)
    return {
        "camera": args.camera,
        **({"perception": perception} if perception else {}),
        **({"localisation": localisation} if localisation else {}),
    }


#: The paper's Table II schedule belongs to the paper home alone (data/schedules/table2.json).
PAPER_HOME = "paper"
PAPER_SCHEDULE = "table2"


def _paper_schedule_only(home: str, what: str, how: str) -> str:
    """The error for a non-paper home asked to run the paper home's Table II schedule."""
    return (
        f"{what} on home {home!r}: its schedule, {PAPER_SCHEDULE} (the paper's Table II), is "
        f"the {PAPER_HOME} home's only; {how}"
    )


def cmd_search(args: argparse.Namespace) -> int:
    from objsearch.agent.categories import Category
    from objsearch.agent.session import Session, load_context
    from objsearch.product import relation_models
    from objsearch.sim.detector_model import with_perception
    from objsearch.sim.localisation import with_localisation
    from objsearch.sim.world import SimClock, SimWorld, with_camera

    ctx = load_context(args.home)
    target = ctx.vocabulary.resolve_target(args.target).name
    pose = ctx.home.start(args.start)
    placements = _search_placements(args, ctx)
    if isinstance(placements, int):
        return placements
    if not any(p.cls == target for p in placements.values()):
        where = (
            f"scene {args.scene} of {args.schedule}"
            if args.scene is not None
            else "its own placements"
        )
        classes = sorted({p.cls for p in placements.values()})
        raise ObjsearchError(
            f"no {target} is placed in {args.home} ({where}), so the simulated search has "
            f"nothing to find; placed: {', '.join(classes) or 'nothing'}"
        )
    tmp = None if args.log else tempfile.mkdtemp(prefix="objsearch-search-")
    log_dir = Path(args.log or tmp or ".")
    try:
        spec, camera = with_camera(
            run_spec(args, ctx.home, schedule=None if args.scene is None else args.schedule)
        )
        spec, detector = with_perception(spec, movable=ctx.vocabulary.names(Category.SEMI_DYNAMIC))
        spec, localiser = with_localisation(spec)
        inputs = {"target": target, "start": args.start, "scene": args.scene}
        if args.new_map:
            inputs["new_map"] = True
        session = Session.start(
            ctx,
            log_dir,
            spec,
            inputs=inputs,
            new_map=args.new_map,
            models=relation_models(simulator=True),
        )
        try:
            world = SimWorld(
                ctx.home,
                ctx.navmap,
                placements,
                pose,
                clock=SimClock(session.resume_time_ns),
                camera=camera,
                detector=detector,
                localiser=localiser,
            )
            oracle = world.oracle_length(
                target, min_mask_px=ctx.vocabulary.classes[target].min_mask_area_px
            )
            result = session.search(world, target, args.start, scene=args.scene)
            # A "found" on a false positive or a confusion is a failure (the agent believed it).
            real = world.is_instance_of(result.found_instance, target)
            map_id = session.state.maps.current
        finally:
            session.close()
    finally:
        if tmp:
            shutil.rmtree(tmp, ignore_errors=True)
    found = result.found_instance if result.success and real else None
    placed = placements.get(found) if found is not None else None
    summary = {
        "target": target,
        "start": args.start,
        "strategy": args.strategy,
        "camera": camera.name,
        "perception": spec.params.get("perception", {"preset": "perfect"})["preset"],
        "localisation": spec.params.get("localisation", {"preset": "perfect"})["preset"],
        "map": map_id,
        "success": result.success and real,
        "false_found": result.success and not real,
        "found": result.found_instance,
        # Where the simulator had placed what was found: its static (inside it, for a closed
        # container) and room; null when nothing of the target's was found.
        "found_at": None
        if placed is None
        else {"static_id": placed.support, "inside": placed.inside, "room": placed.room},
        "path_to_discovery_m": None
        if result.path_to_discovery is None
        else round(result.path_to_discovery, 3),
        "path_length_m": round(result.path_length, 3),
        "oracle_length_m": round(oracle, 3),
        "rooms": [room for room, _ in result.plans],
        "route": [[round(p.x, 2), round(p.y, 2)] for p in result.route],
        "task_id": result.task_id,
        "log": args.log,
    }
    if args.format == "json":
        print(json.dumps(summary, indent=2))
        return 0
    return _print_search(args, target, result, real, placed, found, oracle)


def _search_placements(args: argparse.Namespace, ctx: HomeContext) -> Mapping[str, Placement] | int:
    """Where ``search`` places the objects: the home's own placements, or a scene of
    ``--schedule``; an exit status (the error printed) if that scene is not to be had."""
    from objsearch.sim.placements import base_placements, has_table1_scenario, table1_removals

    if args.scene is None:
        # The Table I removals are the paper home's (and a home whose build derived its own);
        # any other home is searched with its objects as its source scene places them.
        removed = table1_removals(ctx.home) if has_table1_scenario(ctx.home.name) else frozenset()
        return base_placements(ctx.home, removed)
    if args.schedule == PAPER_SCHEDULE and ctx.home.name != PAPER_HOME:
        how = (
            "pass --schedule stats-<seed> (drawn from AI2-THOR placement statistics), "
            "habit-<seed> (objects with habits) or rearr-<seed> (real rearrangements, iTHOR homes "
            "only), e.g. --schedule stats-0"
        )
        return _fail(_paper_schedule_only(ctx.home.name, "search --scene", how))
    # Here, not above: the schedule kinds' generators are for a search in a scheduled scene.
    from objsearch.sim.schedule_names import load_schedule

    schedule = load_schedule(ctx.home, args.schedule)
    if args.scene not in schedule.scenes:
        return _fail(
            f"schedule {args.schedule!r} has scenes {sorted(schedule.scenes)}, not {args.scene}"
        )
    placements: Mapping[str, Placement] = schedule.scenes[args.scene]
    return placements


def _print_search(
    args: argparse.Namespace,
    target: str,
    result: SearchResult,
    real: bool,
    placed: Placement | None,
    found: str | None,
    oracle: float,
) -> int:
    """``search``'s text report; its exit status (1 when the target was not found)."""
    verdict = "found" if result.success and real else "NOT found"
    if result.success and not real:
        verdict += f" (the agent took {result.found_instance} for it: a false sighting)"
    print(f"{verdict}: {target} from {args.start} ({args.strategy})")
    if placed is not None:
        print(f"  {_found_at(placed, found or '', result.path_to_discovery)}")
    for room, order in result.plans:
        print(
            f"  {room}: plan "
            + (" → ".join(s.split("/", 1)[1] for s in order) or "(nothing related)")
        )
    first, last = result.route[0], result.route[-1]
    print(
        f"  route: {len(result.route)} viewpoints from ({first.x:.2f},{first.y:.2f}) "
        f"to ({last.x:.2f},{last.y:.2f}); --format json lists them all"
    )
    print(f"  path length {result.path_length:.2f} m (oracle {oracle:.2f} m)")
    if args.log:
        print(f"  events appended to {args.log} ({result.task_id})")
    return 0 if result.success and real else 1


def _found_at(placed: Placement, instance: str, seen_after: float | None) -> str:
    """Where the search found the target: ``found Apple|… inside Fridge|… in kitchen, seen after
    2.50 m``."""
    if placed.support is None:
        where = "away from the furniture"
    else:
        where = ("inside " if placed.inside else "on ") + placed.support.split("/", 1)[-1]
    seen = "" if seen_after is None else f", seen after {seen_after:.2f} m"
    return f"found {instance} {where} in {placed.room}{seen}"


# -- demo -------------------------------------------------------------------------------------


def cmd_demo(args: argparse.Namespace) -> int:
    import contextlib

    from objsearch.sim.demo import run_demo

    if args.home != PAPER_HOME:
        how = (
            f"for its own schedules run objsearch bench homes --homes {args.home} "
            f"(--schedules stats,habit,rearr), or objsearch search --home {args.home} "
            "--scene N --schedule stats-0"
        )
        return _fail(_paper_schedule_only(args.home, "demo", how))
    # With --format json the human report goes to stderr and stdout holds only the JSON summary.
    with (
        contextlib.redirect_stdout(sys.stderr)
        if args.format == "json"
        else contextlib.nullcontext()
    ):
        code = run_demo(
            out=Path(args.out),
            home=args.home,
            force=args.force,
            progress=not args.no_progress,
            baseline=not args.no_baseline,
            strategy=args.strategy,
            camera=args.camera,
            perception=t.perception_params(args),
            localisation=t.localisation_params(args),
        )
    if args.format == "json" and code == 0:
        print(json.dumps(demo_summary(Path(args.out)), indent=2))
    return code


def demo_summary(out: Path) -> dict[str, Any]:
    """``demo --format json``: the demo's files and, per update mode, its searches from path_lengths.csv."""
    import csv

    modes: dict[str, dict[str, Any]] = {}
    with (out / "path_lengths.csv").open(newline="", encoding="utf-8") as fh:
        for row in csv.DictReader(fh):
            m = modes.setdefault(
                row["update_mode"], {"searches": 0, "found": 0, "length": 0.0, "discovery": 0.0}
            )
            m["searches"] += 1
            m["found"] += row["success"] == "True"
            m["length"] += float(row["path_length"])
            m["discovery"] += float(row["path_to_discovery"])
    return {
        "out": str(out),
        "table": str(out / "path_lengths.csv"),
        "plot": str(out / "path_length_per_scene.png"),
        "logs": {mode: str(out / f"log-{mode}") for mode in modes},
        "modes": {
            mode: {
                "searches": m["searches"],
                "success_rate": round(m["found"] / m["searches"], 4),
                "mean_path_to_discovery_m": round(m["discovery"] / m["searches"], 4),
                "mean_path_length_m": round(m["length"] / m["searches"], 4),
            }
            for mode, m in modes.items()
        },
    }


# -- graph ------------------------------------------------------------------------------------


def cmd_graph(args: argparse.Namespace) -> int:
    from objsearch.product import relation_models
    from objsearch.replay.asof import scene_graph_at

    graph = scene_graph_at(
        Path(args.log),
        args.until,
        models=relation_models(simulator=True),
        progress=lambda events: t.progress(
            events, "graph", " events", enabled=not args.no_progress
        ),
    )
    table = graph.as_table()
    if args.format == "json":
        print(
            json.dumps(
                {"seq": graph.last_seq, "tasks": graph.tasks_folded, "relations": table}, indent=2
            )
        )
        return 0
    statics = sorted({s for row in table.values() for s in row})
    print(f"scene graph at seq {graph.last_seq} ({graph.tasks_folded} tasks folded)")
    width = max(8, *(len(s) + 1 for s in statics))
    print(f"{'':12}" + "".join(f"{s:>{width}}" for s in statics))
    for d, row in table.items():
        print(f"{d:12}" + "".join(f"{row.get(s, 0.0):{width}.4f}" for s in statics))
    return 0


# -- parser -----------------------------------------------------------------------------------

#: Modules that add subcommands: each has ``register(sub)`` taking the subparsers action and keeps
#: its heavy imports inside the command functions, so ``objsearch --help`` stays fast.
COMMAND_MODULES: tuple[str, ...] = (
    "objsearch.cli_bags",
    "objsearch.cli_bench",
    "objsearch.cli_log",
    "objsearch.cli_map",
    "objsearch.cli_query",
    "objsearch.cli_replay",
    "objsearch.cli_runtime",
    "objsearch.cli_where",
)


def _add_build(data_sub: Any) -> None:
    from objsearch.pipeline.findings import FINDING_KINDS

    build = data_sub.add_parser("build", help="convert ../shared/data into data/")
    build.add_argument(
        "--source",
        required=True,
        type=t.existing_dir,
        help="the shared data folder (../shared/data)",
    )
    build.add_argument(
        "--out",
        type=t.dir_path,
        help="output folder (default: $OBJSEARCH_DATA, else data/ of the checkout objsearch runs from)",
    )
    # --home names a home in every other command; a home *made* from iTHOR FloorPlans is --ithor,
    # beside --procthor (the old spelling still works with a note).
    t.renamed(
        build,
        "--home",
        build.add_argument(
            "--ithor",
            action="append",
            type=t.text,
            metavar="NAME=K,L,B,W",
            help="a home from four iTHOR FloorPlans: kitchen, living room, bedroom, bathroom "
            "(repeatable). Without --ithor, --procthor and --heldout-ithor: the committed set "
            "(paper=FloorPlan2,FloorPlan201,FloorPlan303,FloorPlan401, ithor-01..10, the ProcTHOR "
            "houses)",
        ),
    )
    build.add_argument(
        "--procthor",
        action="append",
        type=t.text,
        metavar="NAME=HOUSE.json",
        help="a home from a ProcTHOR house file, relative to --source or absolute (repeatable)",
    )
    build.add_argument(
        "--heldout-ithor",
        type=t.number_spans(1, HELDOUT_ITHOR_MAX),
        **t.LIST,
        metavar="N[-M],...",
        help="held-out iTHOR homes ithor-N by the seeded rule of pipeline/more_homes.py, e.g. 11-14",
    )
    build.add_argument(
        "--accept",
        type=t.subset_of(FINDING_KINDS),
        **t.LIST,
        metavar="KIND,...",
        help="go ahead despite these findings (recorded in PROVENANCE.md): "
        + ", ".join(FINDING_KINDS),
    )
    t.format_option(build, "the build report as JSON")
    t.progress_option(build)
    build.set_defaults(func=cmd_data_build)


def _add_search(sub: Any) -> None:
    search = sub.add_parser("search", help="run one search in the simulated home")
    # Positional as in agent find TARGET and where TARGET (--target, its old spelling, still
    # works with a note).
    t.input_argument(
        search,
        "target",
        type=t.text,
        metavar="TARGET",
        help="object to find, e.g. Apple, phone, cup",
        old=("--target",),
        purpose="to find",
    )
    search.add_argument("--start", required=True, type=t.text, help="start point, e.g. kitchen-1")
    search.add_argument("--home", default="paper", type=t.text, help="home in data/homes (paper)")
    search.defer(_search_options)
    search.add_argument(
        "--scene",
        type=t.SCENE,
        help="place objects as in this scene of the schedule (default: the home's own "
        "placements, with the paper's Table I removals on the paper home)",
    )
    search.add_argument(
        "--schedule",
        default="table2",
        type=t.text,
        help="placement schedule: table2, stats-<seed> or rearr-<seed> (table2)",
    )
    search.add_argument(
        "--log", type=t.dir_path, help="event log folder to append to (default: a temporary one)"
    )
    search.add_argument(
        "--update-mode",
        default="all",
        choices=["none", "targets", "all"],
        help="which experience Eq. 4 folds in at the end of the task (all)",
    )
    search.add_argument(
        "--new-map",
        action="store_true",
        help="this session starts in a new map (the id after the log's latest, map-1 after "
        "map-0): where flags every answer resting on evidence from the map it left",
    )
    t.format_option(search, "print a JSON summary")
    search.set_defaults(func=cmd_search)


def _add_demo(sub: Any) -> None:
    demo = sub.add_parser(
        "demo", help="the long-term schedule (10 scenes × 8 targets × 8 starts) with updates"
    )
    demo.add_argument("--out", default="out/demo", type=t.dir_path, help="output folder (out/demo)")
    demo.add_argument("--home", default="paper", type=t.text, help="home in data/homes (paper)")
    demo.add_argument(
        "--force",
        action="store_true",
        help="replace an earlier demo in --out (only the files that demo wrote; a folder holding "
        "anything else is refused)",
    )
    t.progress_option(demo)
    demo.add_argument("--no-baseline", action="store_true", help="skip the no-update baseline run")
    demo.defer(
        lambda p: p.add_argument(
            "--strategy",
            default="wpl",
            type=t.strategy,
            help="search strategy, NAME or NAME+cover (wpl, the paper's method)",
        )
    )
    t.camera_option(demo)
    t.perception_option(demo)
    t.localisation_option(demo)
    t.format_option(demo, "print a JSON summary (the report goes to stderr)")
    demo.set_defaults(func=cmd_demo)


def _add_graph(sub: Any) -> None:
    graph = sub.add_parser("graph", help="print the scene graph projection of a log")
    t.input_argument(
        graph, "log", type=t.existing_dir, metavar="LOG", help="event log folder", old=("--log",)
    )
    # A sequence number, as replay's --until; where's --at is a time of the week (graph's old
    # spelling, still working with a note).
    t.renamed(
        graph,
        "--at",
        graph.add_argument(
            "--until",
            type=t.int_range(0),
            metavar="SEQ",
            help="as it was right after this event (its sequence number)",
        ),
    )
    t.format_option(graph, "print JSON")
    t.progress_option(graph)
    graph.set_defaults(func=cmd_graph)


def build_parser() -> argparse.ArgumentParser:
    parser = t.Parser(
        prog="objsearch",
        description="Long-term object search with an incrementally updated scene graph.",
    )
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    data = sub.add_parser("data", help="derive the project's data from public sources")
    data_sub = data.add_subparsers(dest="data_command", required=True, metavar="SUBCOMMAND")
    _add_build(data_sub)
    _add_search(sub)
    _add_demo(sub)
    _add_graph(sub)
    for module in COMMAND_MODULES:
        importlib.import_module(module).register(sub)
    return parser


class _VersionAction(argparse.Action):
    """``--version``: like argparse's, but the version is looked up only when asked for (the
    package metadata costs an import most commands never need)."""

    def __init__(self, option_strings: Sequence[str], dest: str = argparse.SUPPRESS) -> None:
        super().__init__(
            option_strings, dest, default=argparse.SUPPRESS, nargs=0, help="show the version"
        )

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: object,
        option_string: str | None = None,
    ) -> None:
        print(f"{parser.prog} {_version()}")
        parser.exit()


def _version() -> str:
    """The installed distribution's version (the package's own if it is not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    from objsearch import __version__

    try:
        return version("objsearch")
    except PackageNotFoundError:
        return __version__


def _search_options(p: argparse.ArgumentParser) -> None:
    """Added when the command is first used: the strategies import the agent."""
    from objsearch.agent.strategies import DEFAULT_STRATEGY, STRATEGIES

    p.add_argument(
        "--strategy",
        default=DEFAULT_STRATEGY,
        type=t.strategy,
        help=f"search strategy: one of {', '.join(STRATEGIES)}, each also as NAME+cover (long "
        "statics looked at from a viewpoint per 1.5 m stretch when nothing was found); the "
        f"paper's method is wpl (default: {DEFAULT_STRATEGY}, chosen by protocol v5, "
        "docs/results-belief.md); objsearch bench compares them",
    )
    p.add_argument("--alpha", type=t.ALPHA, default=10.0, help="alpha of Eq. 3, 0-1000 (10)")
    p.add_argument(
        "--seed",
        type=t.SEED,
        default=0,
        help="seed (SDP's random room order, the simulated detector's draws)",
    )
    t.camera_option(p)
    t.perception_option(p)
    t.localisation_option(p)


def expected_errors() -> tuple[type[BaseException], ...]:
    """The error root that means bad input or a bad environment, not a bug: the CLI reports it
    as ``objsearch: error: …`` (exit 2); anything else still ends in a traceback. The event
    store's and the data converter's errors derive from it too."""
    return (ObjsearchError,)


def _describe(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        return f"{exc.filename}: {exc.strerror}" if exc.filename else exc.strerror
    return str(exc) or type(exc).__name__


def _tolerate_narrow_terminals() -> None:
    """Characters the terminal cannot show (α, →, ° on an ASCII-only one) are written as
    escapes instead of ending the command with UnicodeEncodeError."""
    for stream in (sys.stdout, sys.stderr):
        if isinstance(stream, io.TextIOWrapper) and stream.errors == "strict":
            stream.reconfigure(errors="backslashreplace")


def main(
    argv: Sequence[str] | None = None, *, parser: argparse.ArgumentParser | None = None
) -> int:
    """Run ``objsearch ARGV``; ``parser`` is one :func:`build_parser` made before (the kill-test
    server builds it once for all its commands)."""
    from objsearch.events import TornTailWarning

    _tolerate_narrow_terminals()
    # The event store reports a cut torn tail through logging (for the robot's journal) and as a
    # warning (for library users); on the command line the log line alone is enough.
    logging.basicConfig(format="objsearch: %(levelname)s: %(message)s", level=logging.WARNING)
    warnings.filterwarnings("ignore", category=TornTailWarning)
    parser = parser or build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, or a bad option (already reported as objsearch: error:)
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    try:
        code: int = args.func(args)
    except expected_errors() as exc:
        return _fail(_describe(exc))
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # Output piped into `head` and the like: stop quietly, as Unix tools do.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except OSError as exc:
        # The machine said no (disk full, permission denied, a path that vanished): not a bug.
        return _fail(_describe(exc))
    return code


if __name__ == "__main__":
    sys.exit(main())
