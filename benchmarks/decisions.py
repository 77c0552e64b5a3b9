r"""Decision time of a search's planning, against the paper's WPL in the same run: the
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

    python benchmarks/decisions.py --perception realistic,harsh --homes development-largest \
        --perception-only --scenes 3 --starts 2

times the decisions of whole searches (``global-belief+cover``, ``habit-0`` scenes 1 to
``--scenes``, every target from ``--starts`` starts, confirmation and revisits included) under
each named detector model and under ``perfect`` in the same run. A *decision* is what the robot
waits on: the agent's computation between the end of one simulator call (a drive, a look, an
opening) and the start of the next, and each handling of a detection while it drives (whether
to stop: the sighting's prior and posterior), event logging included, the simulator's own time
excluded. A search's *first decision* runs from the request to its first simulator call: what
the robot waits before it moves. Each model's run starts from freshly loaded maps (as a robot's
process does), and the simulator's oracle walks a map of its own, so no shortest path is built
for the agent outside its decisions. Printed, each with its ratio to ``perfect``'s median:
median, p95 and max of every decision, of the first decisions (and the run's first search's,
the coldest), of the whole-home plans alone; and the run's start (``Session.start_run``, where
the distances between the home's stops are built). ``--homes development-largest``: of the
development homes, the one with the most statics and the one with the most viewpoints.
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from objsearch.agent.catalogue import STORE
from objsearch.agent.detector_model import preset
from objsearch.agent.home import available_homes
from objsearch.agent.navmap import NavigationMap
from objsearch.agent.policy import SearchAgent
from objsearch.agent.recorder import Recorder
from objsearch.agent.session import HomeContext, Session, clear_contexts, load_context
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import RunSpec
from objsearch.agent.world import Detection, Navigation
from objsearch.events.log_read import read_log
from objsearch.events.projection import fold
from objsearch.sim.longterm import TARGET_ORDER, run_schedule
from objsearch.sim.world import SimWorld

#: Scenes of routine-0 in the time-aware belief's memory when its planning is timed (two weeks).
ROUTINE_SCENES = 56
#: The homes the agent was developed on (``--homes development-largest`` picks among them).
DEVELOPMENT_HOMES = ("paper", "ithor-02", "ithor-05", "procthor-00")


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


@dataclass
class DecisionClock:
    """The agent's time between the simulator's calls, one sample per decision."""

    gaps: list[float] = field(default_factory=list)
    plans: list[float] = field(default_factory=list)
    #: each search's first decision (from the request to its first simulator call), also in gaps
    firsts: list[float] = field(default_factory=list)
    #: each run's start (Session.start_run: run_started, the agent and its stop table)
    run_starts: list[float] = field(default_factory=list)
    _since: float | None = None
    _first: bool = False

    def world_call(self, call: Callable[[], Any]) -> Any:
        t0 = time.perf_counter()
        if self._since is not None:
            self.gaps.append(t0 - self._since)
            if self._first:
                self.firsts.append(t0 - self._since)
                self._first = False
        try:
            return call()
        finally:
            self._since = time.perf_counter()

    def handler(self, handle: Callable[[Detection, Any], bool]) -> Callable[[Detection, Any], bool]:
        def timed(det: Detection, pose: Any) -> bool:
            t0 = time.perf_counter()
            try:
                return handle(det, pose)
            finally:
                self.gaps.append(time.perf_counter() - t0)

        return timed


@contextmanager
def timed_decisions(clock: DecisionClock) -> Iterator[None]:
    """Time every decision of the searches run inside (see the module doc)."""
    navigate, look, opening = SimWorld.navigate, SimWorld.look, SimWorld.open
    search, plan_global = SearchAgent.search, SearchAgent.plan_global
    oracle, start_run = SimWorld.oracle_length, Session.start_run
    # The simulator's oracle walks the robot's map from each start before the search: on the
    # agent's own map that would build, outside the timed decisions, the shortest paths a robot
    # builds in its first decision. It walks a map of its own.
    oracle_maps: dict[int, NavigationMap] = {}

    def timed_navigate(self: SimWorld, goal: Any, **kw: Any) -> Navigation:
        handle = kw.get("on_detection")
        if handle is not None:
            kw["on_detection"] = clock.handler(handle)
        result: Navigation = clock.world_call(lambda: navigate(self, goal, **kw))
        return result

    def timed_look(self: SimWorld, *a: Any) -> tuple[Detection, ...]:
        result: tuple[Detection, ...] = clock.world_call(lambda: look(self, *a))
        return result

    def timed_open(self: SimWorld, *a: Any) -> tuple[Detection, ...]:
        result: tuple[Detection, ...] = clock.world_call(lambda: opening(self, *a))
        return result

    def timed_search(self: SearchAgent, *a: Any, **kw: Any) -> Any:
        clock._since = time.perf_counter()
        clock._first = True
        try:
            return search(self, *a, **kw)
        finally:
            assert clock._since is not None
            clock.gaps.append(time.perf_counter() - clock._since)
            if clock._first:  # a search that never moved: its only decision is its first
                clock.firsts.append(clock.gaps[-1])
            clock._since = None
            clock._first = False

    def timed_plan(self: SearchAgent, *a: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return plan_global(self, *a)
        finally:
            clock.plans.append(time.perf_counter() - t0)

    def own_map_oracle(self: SimWorld, cls: str, **kw: Any) -> float:
        agents = self.navmap
        self.navmap = oracle_maps.setdefault(id(agents), NavigationMap.from_home(self.home))
        try:
            return oracle(self, cls, **kw)
        finally:
            self.navmap = agents

    def timed_start_run(self: Session, *a: Any, **kw: Any) -> None:
        t0 = time.perf_counter()
        try:
            start_run(self, *a, **kw)
        finally:
            clock.run_starts.append(time.perf_counter() - t0)

    patches: dict[tuple[type, str], Any] = {
        (SimWorld, "oracle_length"): own_map_oracle,
        (Session, "start_run"): timed_start_run,
        (SimWorld, "navigate"): timed_navigate,
        (SimWorld, "look"): timed_look,
        (SimWorld, "open"): timed_open,
        (SearchAgent, "search"): timed_search,
        (SearchAgent, "plan_global"): timed_plan,
    }
    originals = {key: getattr(*key) for key in patches}
    try:
        for (owner, name), fn in patches.items():
            setattr(owner, name, fn)
        yield
    finally:
        for (owner, name), fn in originals.items():
            setattr(owner, name, fn)


def search_decisions(home: str, perception: str, scenes: int, starts: int) -> DecisionClock:
    """Every decision of ``global-belief+cover``'s searches of ``habit-0`` scenes 1 to
    ``scenes`` on ``home``, each target from ``starts`` starts, under ``perception``. The run
    starts from freshly loaded maps, as a robot's process does: no shortest path another run
    built is in them."""
    clear_contexts()
    ctx = load_context(home)
    model = preset(perception)
    params = {} if model.perfect else {"perception": model.params()}
    spec = RunSpec.for_home(ctx.home, "global-belief+cover", schedule="habit-0", params=params)
    clock = DecisionClock()
    with tempfile.TemporaryDirectory() as tmp, timed_decisions(clock):
        run_schedule(
            Path(tmp),
            spec,
            scenes=range(1, scenes + 1),
            starts_per_search=starts,
            skip_absent_targets=True,
        )
    return clock


def _quantile(xs: list[float], q: int) -> float:
    """The q-th percentile of ``xs`` (statistics.quantiles' default method)."""
    return statistics.quantiles(xs, n=100)[q - 1] if len(xs) > 1 else xs[0]


def _spread(xs: list[float]) -> str:
    return (
        f"median {statistics.median(xs) * 1e3:8.3f} ms   p95 {_quantile(xs, 95) * 1e3:8.3f} ms   "
        f"max {max(xs) * 1e3:8.2f} ms   (n = {len(xs)})"
    )


def perception_report(home: str, models: list[str], scenes: int, starts: int) -> None:
    """Decision times under each of ``models`` against ``perfect``'s, in the same run: every
    decision, and each search's first apart (the run's first search, whose caches are cold,
    named on its own)."""
    runs = {name: search_decisions(home, name, scenes, starts) for name in ["perfect", *models]}
    base = runs["perfect"]
    mb, pb, fb = (statistics.median(x) for x in (base.gaps, base.plans, base.firsts))
    for name, clock in runs.items():
        m, p, f = (statistics.median(x) for x in (clock.gaps, clock.plans, clock.firsts))
        print(
            f"{home}: {name:9s} every decision  {_spread(clock.gaps)}   ratio to perfect "
            f"{m / mb:5.2f}; target <= 50 ms"
        )
        print(
            f"{home}: {name:9s} first decision  {_spread(clock.firsts)}   ratio to perfect "
            f"{f / fb:5.2f}; the run's first search's {clock.firsts[0] * 1e3:8.2f} ms"
        )
        print(
            f"{home}: {name:9s} whole-home plan {_spread(clock.plans)}   ratio to perfect "
            f"{p / pb:5.2f}"
        )
        print(f"{home}: {name:9s} run start       {_spread(clock.run_starts)}")


def development_largest() -> list[str]:
    """Of the development homes, the one with the most mapped statics (the most stops a
    decision plans over) and the one with the most viewpoints (the longest shortest paths), in
    that order; one home when both are the same."""
    contexts = {name: load_context(name) for name in DEVELOPMENT_HOMES}
    by_statics = max(contexts, key=lambda n: (len(contexts[n].semmap.statics), n))
    by_viewpoints = max(contexts, key=lambda n: (len(contexts[n].navmap.room_of), n))
    return list(dict.fromkeys([by_statics, by_viewpoints]))


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
    ap.add_argument(
        "--perception",
        default="",
        help="detector models (realistic,harsh) whose searches' decisions are timed against "
        "perfect's in the same run",
    )
    ap.add_argument(
        "--starts", type=int, default=2, help="starts per target and scene (--perception)"
    )
    ap.add_argument(
        "--perception-only", action="store_true", help="time only the --perception searches"
    )
    args = ap.parse_args()
    if args.homes == "largest":
        homes = largest_homes()
    elif args.homes == "development-largest":
        homes = development_largest()
    else:
        homes = args.homes.split(",")
    models = [m for m in args.perception.split(",") if m]
    for home in homes:
        if models:
            perception_report(home, models, args.scenes, args.starts)
        if args.perception_only:
            continue
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
