"""The whole-home planner (method ``global``): one plan over every stop, its decision, and the
search that executes it room segment by room segment."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from objsearch.agent.catalogue import STORE, PlanComputed, decode
from objsearch.agent.planner import epl_terms
from objsearch.agent.policy import GLOBAL_EXACT_STOPS, SearchAgent, SearchConfig
from objsearch.agent.recorder import Recorder
from objsearch.agent.scene_graph import SceneGraphProjection
from objsearch.agent.session import load_context
from objsearch.agent.stops import Stop
from objsearch.agent.strategies import RunSpec
from objsearch.events import read_log
from objsearch.sim.longterm import run_schedule


class _PlanOnly:
    def append_record(self, *args: object, **kwargs: object) -> object:
        raise AssertionError("planning only")


def _agent() -> SearchAgent:
    ctx = load_context("paper")
    return SearchAgent(
        ctx.navmap,
        ctx.semmap,
        ctx.vocabulary,
        SceneGraphProjection(),
        Recorder(_PlanOnly(), ()),  # type: ignore[arg-type]
        SearchConfig(),
    )


def _stops(agent: SearchAgent, per_room: int, seed: int) -> dict[str, list[Stop]]:
    rng = np.random.default_rng(seed)
    out: dict[str, list[Stop]] = {}
    for room in agent.rooms:
        statics = sorted(agent.semmap.in_room(room), key=lambda s: s.id)[:per_room]
        out[room] = [Stop((s,), float(rng.uniform(0.05, 1.0))) for s in statics]
    return out


@pytest.mark.parametrize("seed", range(3))
def test_the_plan_is_the_best_of_all_orders_over_every_room(seed: int) -> None:
    agent = _agent()
    remaining = _stops(agent, 2, seed)
    flat = [(r, s) for r in agent.rooms for s in remaining[r]]
    assert 2 < len(flat) <= 8
    here = agent.navmap.doors[agent.rooms[0]]
    plan = agent.plan_global(here, remaining)
    assert plan is not None and plan.ordering.exact
    nav = agent.navmap
    start = np.array([nav.distance(here, s.viewpoint) for _, s in flat])
    dist = np.array([[nav.distance(a.viewpoint, b.viewpoint) for _, b in flat] for _, a in flat])
    rel = np.array([s.rel for _, s in flat])
    prob = rel / rel.sum()
    best = min(
        math.fsum(epl_terms(order, start, dist, prob, None))
        for order in itertools.permutations(range(len(flat)))
    )
    assert plan.ordering.value == pytest.approx(best, rel=1e-9)
    # The decision: the first stop's room, that room's stops in the plan's order, the segment
    # searched before the plan leaves it, and the rooms in the order the plan enters them.
    first = flat[plan.ordering.order[0]]
    assert plan.room == first[0] == plan.rooms[0]
    assert set(plan.order) == set(remaining[plan.room])
    assert 1 <= plan.segment <= len(plan.order)
    entered = [flat[k][0] for k in plan.ordering.order]
    assert [r for i, r in enumerate(entered) if i == 0 or entered[i - 1] != r] == list(plan.rooms)


def test_a_big_home_is_planned_by_the_bounded_approximation_and_nothing_left_is_none() -> None:
    agent = _agent()
    remaining = _stops(agent, 99, 0)
    assert sum(map(len, remaining.values())) > GLOBAL_EXACT_STOPS
    plan = agent.plan_global(agent.navmap.doors[agent.rooms[0]], remaining)
    assert plan is not None and not plan.ordering.exact
    assert len(plan.ordering.order) == sum(map(len, remaining.values()))
    assert agent.plan_global(agent.navmap.doors[agent.rooms[0]], {}) is None


def test_a_global_search_replans_at_each_room_and_never_searches_a_stop_twice(
    tmp_path: Path,
) -> None:
    spec = RunSpec.for_home(load_context("paper").home, "global-belief", schedule="table2")
    run_schedule(tmp_path / "log", spec, scenes=(1,), targets=("Apple",), starts=("kitchen-2",))
    plans = [
        decode(e, PlanComputed)
        for e in read_log(tmp_path / "log", store=STORE)
        if e.type == "plan_computed"
    ]
    assert plans and all(p.objective.startswith("global-epl") for p in plans)
    looked: list[str] = []
    for e in read_log(tmp_path / "log", store=STORE):
        if e.type in ("view_taken", "container_opened") and e.payload.get("reason") != "cover":
            looked.append(str(e.payload["static_id"]))
    # A view of each of a static's three yaws repeats its id; a static is never searched again
    # after the search moved on to another one.
    runs = [k for k, _ in itertools.groupby(looked)]
    assert len(runs) == len(set(runs))
