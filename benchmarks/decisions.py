"""Decision time of a search's planning — room order plus every room's stop order — for the
expected-cost room order on the per-instance memory against the paper's WPL, in the same run.

    python benchmarks/decisions.py [--homes ithor-02,procthor-02] [--scenes 2]

Each strategy first runs ``--scenes`` scenes of ``habit-0`` (so its memory holds something), then
the planning of one search (what ``SearchAgent.search`` computes before and between moves) is timed
for every target from every start. Medians and the ratio are printed; the target is ≤ 50 ms.
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
from pathlib import Path

from objsearch.agent.catalogue import STORE
from objsearch.agent.policy import Recorder, SearchAgent
from objsearch.agent.session import load_context
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import RunSpec
from objsearch.events.log import read_log
from objsearch.events.projection import fold
from objsearch.sim.longterm import TARGET_ORDER, run_schedule


class _NoSink:
    def append(self, *args: object, **kwargs: object) -> object:
        raise AssertionError("planning only")


def plan_times(home: str, strategy: str, scenes: int) -> list[float]:
    ctx = load_context(home)
    spec = RunSpec.for_home(ctx.home, strategy, schedule="habit-0")
    with tempfile.TemporaryDirectory() as tmp:
        run_schedule(Path(tmp), spec, scenes=range(1, scenes + 1), skip_absent_targets=True)
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--homes", default="ithor-02,procthor-02")
    ap.add_argument("--scenes", type=int, default=2)
    args = ap.parse_args()
    for home in args.homes.split(","):
        base = plan_times(home, "wpl", args.scenes)
        ours = plan_times(home, "ecost-memory", args.scenes)
        mb, mo = statistics.median(base), statistics.median(ours)
        print(
            f"{home}: median planning per search  wpl {mb * 1e3:7.2f} ms   "
            f"ecost-memory {mo * 1e3:7.2f} ms   ratio {mo / mb:5.2f}   "
            f"max {max(ours) * 1e3:7.2f} ms   (n = {len(ours)}; target <= 50 ms)"
        )


if __name__ == "__main__":
    main()
