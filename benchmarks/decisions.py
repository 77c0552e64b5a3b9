"""Decision time of a search's planning, against the paper's WPL in the same run: the
expected-cost room order on the memory (room order plus every room's stop order), and the
whole-home planner on the belief (``global-belief``: each of a search's decisions, one per room
segment, timed on its own).

    python benchmarks/decisions.py [--homes ithor-02,procthor-02] [--scenes 2]

Each strategy first runs ``--scenes`` scenes of ``habit-0`` (so its memory holds something), then
the planning of one search (what ``SearchAgent.search`` computes before and between moves) is timed
for every target from every start (``ecost-routine``: after two weeks of ``routine-0``, one start
per target; ``ecost-routine-pooled`` the same). ``--routine-only`` times only those two and
``wpl``. ``--homes largest`` takes the bundled iTHOR and ProcTHOR homes
with the most mapped statics. Medians and ratios are printed; the target is ≤ 50 ms a decision.
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
from pathlib import Path

from objsearch.agent.catalogue import STORE
from objsearch.agent.home import available_homes
from objsearch.agent.policy import Recorder, SearchAgent
from objsearch.agent.session import HomeContext, load_context
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import RunSpec
from objsearch.events.log_read import read_log
from objsearch.events.projection import fold
from objsearch.sim.longterm import TARGET_ORDER, run_schedule

#: Scenes of routine-0 in the time-aware belief's memory when its planning is timed (two weeks).
ROUTINE_SCENES = 56


class _NoSink:
    def append_record(self, *args: object, **kwargs: object) -> object:
        raise AssertionError("planning only")


def planning_agent(
    home: str,
    strategy: str,
    scenes: int,
    schedule: str = "habit-0",
    starts_per_search: int | None = None,
) -> tuple[HomeContext, SearchAgent]:
    """A planning-only agent of ``strategy`` whose memory holds ``scenes`` scenes of
    ``schedule`` (each target from every start, or from ``starts_per_search`` of them)."""
    ctx = load_context(home)
    spec = RunSpec.for_home(ctx.home, strategy, schedule=schedule)
    with tempfile.TemporaryDirectory() as tmp:
        run_schedule(
            Path(tmp),
            spec,
            scenes=range(1, scenes + 1),
            starts_per_search=starts_per_search,
            skip_absent_targets=True,
        )
        state = fold(read_log(Path(tmp), store=STORE), AgentState())
    agent = SearchAgent(
        ctx.navmap,
        ctx.semmap,
        ctx.vocabulary,
        state.graph(),
        Recorder(_NoSink(), ()),  # type: ignore[arg-type]
        spec.config(),
        spec.stop_planner(),
    )
    return ctx, agent


def plan_times(
    home: str, strategy: str, scenes: int, schedule: str = "habit-0", starts: int | None = None
) -> list[float]:
    ctx, agent = planning_agent(home, strategy, scenes, schedule, starts)
    times: list[float] = []
    for target in TARGET_ORDER:
        for pose in ctx.home.starts.values():
            t0 = time.perf_counter()
            here = pose.point
            start_room = ctx.navmap.room_at(here.x, here.y)
            rooms = agent.room_order(start_room, target, "bench", here=here)
            room_stops = {r: agent.stops(r, target) for r in rooms}
            for i, r in enumerate(rooms):
                later = rooms[i + 1 :]
                agent.order_stops(
                    here,
                    room_stops[r],
                    next_entry=ctx.navmap.doors[later[0]] if later else None,
                    rest_mass=math.fsum(s.rel for q in later for s in room_stops[q]),
                )
                here = ctx.navmap.doors[later[0]] if later else here
            times.append(time.perf_counter() - t0)
    return times


def global_decision_times(home: str, scenes: int) -> tuple[list[float], list[float]]:
    """Each decision of ``global-belief``'s searches, walked as the search walks it when the
    target is nowhere (every segment, to the last stop): the most decisions a search can take.
    Returns every decision's time and each search's first (the largest problem)."""
    ctx, agent = planning_agent(home, "global-belief", scenes)
    times: list[float] = []
    firsts: list[float] = []
    for target in TARGET_ORDER:
        for pose in ctx.home.starts.values():
            firsts_before = len(times)
            here = pose.point
            remaining = {r: list(agent.stops(r, target)) for r in agent.rooms}
            while True:
                t0 = time.perf_counter()
                plan = agent.plan_global(here, remaining)
                times.append(time.perf_counter() - t0)
                if plan is None:
                    break
                for stop in plan.order[: plan.segment]:
                    remaining[plan.room].remove(stop)
                here = plan.order[plan.segment - 1].viewpoint
            firsts.append(times[firsts_before])
    return times, firsts


def largest_homes() -> list[str]:
    """The bundled iTHOR and ProcTHOR homes with the most mapped statics."""
    best: dict[str, tuple[int, str]] = {}
    for name in available_homes():
        family = name.split("-")[0]
        if family not in ("ithor", "procthor"):
            continue
        size = len(load_context(name).semmap.statics)
        best[family] = max(best.get(family, (0, "")), (size, name))
    return [name for _, name in best.values()]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--homes", default="ithor-02,procthor-02")
    ap.add_argument("--scenes", type=int, default=2)
    ap.add_argument(
        "--routine-only",
        action="store_true",
        help="time only the beliefs that know the hour (and wpl, the baseline)",
    )
    args = ap.parse_args()
    homes = largest_homes() if args.homes == "largest" else args.homes.split(",")
    for home in homes:
        base = plan_times(home, "wpl", args.scenes)
        mb = statistics.median(base)
        # The beliefs that know the hour, after two weeks of a routine schedule (56 scenes, one
        # start per target: every slot and day type holds a belief of its own).
        for routine in ("ecost-routine", "ecost-routine-pooled"):
            timed = plan_times(home, routine, ROUTINE_SCENES, "routine-0", 1)
            mt = statistics.median(timed)
            print(
                f"{home}: median planning per search  {routine} {mt * 1e3:7.2f} ms   ratio to "
                f"wpl {mt / mb:5.2f}   max {max(timed) * 1e3:7.2f} ms   (n = {len(timed)}; "
                f"{ROUTINE_SCENES} scenes of routine-0; target <= 50 ms)"
            )
        if args.routine_only:
            continue
        ours = plan_times(home, "ecost-memory", args.scenes)
        whole, firsts = global_decision_times(home, args.scenes)
        mo, mg, mf = (statistics.median(x) for x in (ours, whole, firsts))
        print(
            f"{home}: median planning per search  wpl {mb * 1e3:7.2f} ms   "
            f"ecost-memory {mo * 1e3:7.2f} ms   ratio {mo / mb:5.2f}   "
            f"max {max(ours) * 1e3:7.2f} ms   (n = {len(ours)}; target <= 50 ms)"
        )
        print(
            f"{home}: median global-belief decision {mg * 1e3:7.2f} ms   ratio to wpl's search "
            f"{mg / mb:5.2f}   p90 {statistics.quantiles(whole, n=10)[-1] * 1e3:7.2f} ms   "
            f"max {max(whole) * 1e3:7.2f} ms   (n = {len(whole)}; target <= 50 ms)"
        )
        print(
            f"{home}: median global-belief first decision of a search {mf * 1e3:7.2f} ms   "
            f"max {max(firsts) * 1e3:7.2f} ms   (n = {len(firsts)})"
        )


if __name__ == "__main__":
    main()
