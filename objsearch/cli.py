"""The ``objsearch`` command line."""

from __future__ import annotations

import argparse
import importlib
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

from objsearch.agent.errors import ObjsearchError

if TYPE_CHECKING:
    from objsearch.sim.world import Placement

EXIT_USAGE = 2


def _fail(message: str) -> int:
    print(f"objsearch: error: {message}", file=sys.stderr)
    return EXIT_USAGE


# -- data -------------------------------------------------------------------------------------


def cmd_data_build(args: argparse.Namespace) -> int:
    from objsearch.paths import build_output_dir
    from objsearch.pipeline.build import build_data, parse_home_arg
    from objsearch.pipeline.errors import BuildError

    try:
        homes = dict(parse_home_arg(spec) for spec in args.home) if args.home else None
        report = build_data(
            Path(args.source),
            build_output_dir(args.out),
            homes=homes,
            progress=lambda line: print(line, file=sys.stderr),
        )
    except BuildError as exc:
        return _fail(str(exc))
    for note in report.notes:
        print(note)
    for path in report.files:
        print(f"wrote {path}")
    return 0


# -- search -----------------------------------------------------------------------------------


def _config(args: argparse.Namespace) -> Any:
    from objsearch.agent.policy import Method, SearchConfig

    return SearchConfig(method=Method(args.method), alpha=args.alpha, seed=args.seed)


def cmd_search(args: argparse.Namespace) -> int:
    from objsearch.agent.scene_graph import UpdateMode
    from objsearch.agent.session import Session, load_context
    from objsearch.sim.schedule import base_placements, table1_removals
    from objsearch.sim.schedules import load_schedule
    from objsearch.sim.world import SimClock, SimWorld

    ctx = load_context(args.home)
    target = ctx.vocabulary.resolve_target(args.target).name
    pose = ctx.home.start(args.start)
    placements: Mapping[str, Placement]
    if args.scene is None:
        placements = base_placements(ctx.home, table1_removals(ctx.home))
    else:
        schedule = load_schedule(ctx.home, args.schedule)
        if args.scene not in schedule.scenes:
            return _fail(
                f"schedule {args.schedule!r} has scenes {sorted(schedule.scenes)}, not {args.scene}"
            )
        placements = schedule.scenes[args.scene]
    tmp = None if args.log else tempfile.mkdtemp(prefix="objsearch-search-")
    log_dir = Path(args.log or tmp or ".")
    try:
        session = Session(ctx, log_dir, _config(args), UpdateMode(args.update_mode))
        try:
            world = SimWorld(
                ctx.home, ctx.navmap, placements, pose, clock=SimClock(session.resume_time_ns)
            )
            oracle = world.oracle_length(target)
            result = session.search(world, target, args.start, scene=args.scene)
        finally:
            session.close()
    finally:
        if tmp:
            shutil.rmtree(tmp, ignore_errors=True)
    summary = {
        "target": target,
        "start": args.start,
        "method": args.method,
        "success": result.success,
        "found": result.found_instance,
        "path_length_m": round(result.path_length, 3),
        "oracle_length_m": round(oracle, 3),
        "rooms": [room for room, _ in result.plans],
        "route": [[round(p.x, 2), round(p.y, 2)] for p in result.route],
        "task_id": result.task_id,
        "log": args.log,
    }
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print(
        f"{'found' if result.success else 'NOT found'}: {target} from {args.start} ({args.method})"
    )
    for room, order in result.plans:
        print(
            f"  {room}: plan "
            + (" → ".join(s.split("/", 1)[1] for s in order) or "(nothing related)")
        )
    first, last = result.route[0], result.route[-1]
    print(
        f"  route: {len(result.route)} viewpoints from ({first.x:.2f},{first.y:.2f}) "
        f"to ({last.x:.2f},{last.y:.2f}); --json lists them all"
    )
    print(f"  path length {result.path_length:.2f} m (oracle {oracle:.2f} m)")
    if args.log:
        print(f"  events appended to {args.log} ({result.task_id})")
    return 0 if result.success else 1


# -- demo -------------------------------------------------------------------------------------


def cmd_demo(args: argparse.Namespace) -> int:
    from objsearch.sim.demo import run_demo

    return run_demo(
        out=Path(args.out),
        home=args.home,
        force=args.force,
        progress=not args.no_progress,
        baseline=not args.no_baseline,
    )


# -- graph ------------------------------------------------------------------------------------


def cmd_graph(args: argparse.Namespace) -> int:
    from objsearch.replay.asof import scene_graph_at

    graph = scene_graph_at(Path(args.log), args.at)
    table = graph.as_table()
    if args.json:
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
    "objsearch.cli_map",
    "objsearch.cli_query",
    "objsearch.cli_replay",
    "objsearch.cli_runtime",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="objsearch",
        description="Long-term object search with an incrementally updated scene graph.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    data = sub.add_parser("data", help="derive the project's data from public sources")
    data_sub = data.add_subparsers(dest="data_command", required=True, metavar="SUBCOMMAND")
    build = data_sub.add_parser("build", help="convert ../shared/data into data/")
    build.add_argument("--source", required=True, help="the shared data folder (../shared/data)")
    build.add_argument(
        "--out",
        help="output folder (default: $OBJSEARCH_DATA, else data/ of the checkout objsearch runs from)",
    )
    build.add_argument(
        "--home",
        action="append",
        metavar="NAME=K,L,B,W",
        help="a home from four iTHOR FloorPlans: kitchen, living room, bedroom, bathroom "
        "(default: paper=FloorPlan2,FloorPlan201,FloorPlan303,FloorPlan401)",
    )
    build.set_defaults(func=cmd_data_build)

    search = sub.add_parser("search", help="run one search in the simulated home")
    search.add_argument("--target", required=True, help="object to find, e.g. Apple, phone, cup")
    search.add_argument("--start", required=True, help="start point, e.g. kitchen-1")
    _search_options(search)
    search.add_argument(
        "--scene",
        type=int,
        help="place objects as in this scene of the schedule "
        "(default: the home's own placements, with the paper's Table I removals)",
    )
    search.add_argument(
        "--schedule",
        default="table2",
        help="placement schedule: table2, stats-<seed> or rearr-<seed> (table2)",
    )
    search.add_argument("--log", help="event log folder to append to (default: a temporary one)")
    search.add_argument(
        "--update-mode",
        default="all",
        choices=["none", "targets", "all"],
        help="which experience Eq. 4 folds in at the end of the task (all)",
    )
    search.add_argument("--json", action="store_true", help="print a JSON summary")
    search.set_defaults(func=cmd_search)

    demo = sub.add_parser(
        "demo", help="the long-term schedule (10 scenes × 8 targets × 8 starts) with updates"
    )
    demo.add_argument("--out", default="out/demo", help="output folder (out/demo)")
    demo.add_argument("--home", default="paper")
    demo.add_argument("--force", action="store_true", help="replace an earlier demo in --out")
    demo.add_argument("--no-progress", action="store_true", help="no progress bar")
    demo.add_argument("--no-baseline", action="store_true", help="skip the no-update baseline run")
    demo.set_defaults(func=cmd_demo)

    graph = sub.add_parser("graph", help="print the scene graph projection of a log")
    graph.add_argument("--log", required=True, help="event log folder")
    graph.add_argument("--at", type=int, help="as it was right after this sequence number")
    graph.add_argument("--json", action="store_true")
    graph.set_defaults(func=cmd_graph)

    for module in COMMAND_MODULES:
        importlib.import_module(module).register(sub)
    return parser


def _search_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--home", default="paper", help="home in data/homes (paper)")
    p.add_argument("--method", default="wpl", choices=["wpl", "rvp", "sdp"], help="planner (wpl)")
    p.add_argument("--alpha", type=float, default=10.0, help="α of Eq. 3 (10)")
    p.add_argument("--seed", type=int, default=0, help="seed (SDP's random room order)")


def main(argv: Sequence[str] | None = None) -> int:
    from objsearch.events import EventStoreError, TornTailWarning

    # The event store reports a cut torn tail through logging (for the robot's journal) and as a
    # warning (for library users); on the command line the log line alone is enough.
    logging.basicConfig(format="objsearch: %(levelname)s: %(message)s", level=logging.WARNING)
    warnings.filterwarnings("ignore", category=TornTailWarning)
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code: int = args.func(args)
    except (ObjsearchError, EventStoreError) as exc:
        return _fail(str(exc))
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # Output piped into `head` and the like: stop quietly, as Unix tools do.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    return code


if __name__ == "__main__":
    sys.exit(main())
