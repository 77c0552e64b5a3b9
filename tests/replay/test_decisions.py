"""Replay reports exactly the decisions a parameter change alters, and why."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.planner import wpl_plan
from objsearch.agent.session import load_context
from objsearch.cli import main
from objsearch.events import read_log
from objsearch.replay.decisions import Overrides, replay
from objsearch.replay.state import ReplayState

LOG = Path(__file__).resolve().parent / "golden" / "sim-wpl-updates"


def _independent_orders(alpha: float) -> dict[int, tuple[str, ...]]:
    """Each recorded plan re-solved straight from its own payload (candidates, Rel) and the
    robot's pose, with the planner alone: no replay code involved."""
    nav = load_context("paper").navmap
    state = ReplayState()
    orders = {}
    for event in read_log(LOG, store=STORE):
        if event.type == "plan_computed":
            assert state.pose is not None
            cands = event.payload["candidates"]
            vps = [tuple(c["viewpoint"]) for c in cands]
            pts = [next(p for p in nav.room_of if (p.x, p.y) == vp) for vp in vps]
            start = np.array([nav.distance(state.pose.point, p) for p in pts])
            dist = np.array([[nav.distance(a, b) for b in pts] for a in pts])
            rel = np.array([c["rel"] for c in cands])
            plan = wpl_plan(start, dist, rel, alpha)
            orders[event.seq] = tuple(cands[k]["static_id"] for k in plan.order)
        state.apply(event)
    return orders


def test_unchanged_parameters_reproduce_every_decision() -> None:
    replayer = replay(read_log(LOG, store=STORE))
    assert len(replayer.decisions) > 10
    assert all(d.same for d in replayer.decisions)
    assert all(
        d.replayed_value == pytest.approx(d.recorded_value, abs=1e-6) for d in replayer.decisions
    )


def test_another_alpha_reports_exactly_the_decisions_it_changes() -> None:
    recorded = {
        e.seq: tuple(e.payload["order"])
        for e in read_log(LOG, store=STORE)
        if e.type == "plan_computed"
    }
    expected = _independent_orders(3.0)
    should_change = {seq for seq in recorded if expected[seq] != recorded[seq]}
    assert should_change, "α = 3 should change some plan of this log"

    replayer = replay(read_log(LOG, store=STORE), overrides=Overrides(alpha=3.0))
    changed = {d.seq for d in replayer.decisions if not d.same}
    assert changed == should_change
    for d in replayer.decisions:
        assert d.replayed_order == expected[d.seq]
        if not d.same:
            assert d.reasons == ("α 10.0 → 3.0",)
            assert d.replayed_value <= d.recorded_value_today + 1e-9  # today's optimum


def test_replay_until_stops_there() -> None:
    plans = [e.seq for e in read_log(LOG, store=STORE) if e.type == "plan_computed"]
    replayer = replay(read_log(LOG, store=STORE), until_seq=plans[2])
    assert [d.seq for d in replayer.decisions] == plans[:3]


def test_cli_exit_status_says_whether_anything_changed(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["replay", str(LOG)]) == 0
    assert "0 with another object order" in capsys.readouterr().out
    assert main(["replay", str(LOG), "--alpha", "3"]) == 1
    out = capsys.readouterr().out
    assert "DIFFERENT" in out and "because α 10.0 → 3.0" in out


def test_a_log_with_plans_but_no_run_is_refused() -> None:
    events = [e for e in read_log(LOG, store=STORE) if e.type != "run_started"]
    with pytest.raises(ObjsearchError, match="incomplete"):
        replay(events)


def test_a_log_of_an_older_schema_version_replays_through_the_upcasters() -> None:
    old = Path(__file__).parent.parent / "events" / "fixtures" / "v1-log"
    assert any(
        e.version == 1 for e in read_log(old, upcast=False, store=STORE) if e.type == "detection"
    )
    replayer = replay(read_log(old, store=STORE))
    assert replayer.decisions
    assert all(d.same for d in replayer.decisions)


@pytest.mark.parametrize("name", ["epl", "wpl-neg-decay"])
def test_runs_of_other_strategies_replay_with_their_own_model_and_planner(
    tmp_path: Path, name: str
) -> None:
    from objsearch.agent.session import load_context
    from objsearch.agent.strategies import RunSpec
    from objsearch.sim.longterm import run_schedule

    spec = RunSpec.for_home(load_context("paper").home, name, schedule="table2")
    run_schedule(
        tmp_path,
        spec,
        scenes=(1, 2),
        targets=("Apple", "Vase"),
        starts=("kitchen-2", "bedroom-1"),
    )
    replayer = replay(read_log(tmp_path, store=STORE))
    assert len(replayer.decisions) >= 8
    assert all(d.same for d in replayer.decisions), [
        d.as_dict() for d in replayer.decisions if not d.same
    ]
    # Replayed as the paper's method instead, some plan must come out differently.
    paper = replay(read_log(tmp_path, store=STORE), overrides=Overrides(strategy="wpl"))
    assert any(not d.same for d in paper.decisions)


def test_a_run_of_the_pooled_belief_that_knows_the_hour_replays_to_the_same_decisions(
    tmp_path: Path,
) -> None:
    from objsearch.agent.routine_belief import PooledRoutineBelief
    from objsearch.agent.state import AgentState
    from objsearch.agent.strategies import RunSpec
    from objsearch.sim.longterm import run_schedule

    spec = RunSpec.for_home(
        load_context("paper").home, "ecost-routine-pooled", schedule="routine-0"
    )
    run_schedule(
        tmp_path, spec, scenes=tuple(range(1, 9)), targets=("Apple", "Cup"), starts_per_search=1
    )
    events = list(read_log(tmp_path, store=STORE))
    assert all(e.payload["clock"] is not None for e in events if e.type == "task_started")
    replayer = replay(events)
    assert len(replayer.decisions) >= 16
    assert all(d.same for d in replayer.decisions), [
        d.as_dict() for d in replayer.decisions if not d.same
    ]
    # The fold is the pooled belief, and it learned a home mixture from the run's clocks.
    state = AgentState()
    for event in events:
        state.apply(event)
    belief = state.graph()
    assert isinstance(belief, PooledRoutineBelief) and belief.pooled_episodes > 0
