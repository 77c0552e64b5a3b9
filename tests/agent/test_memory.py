"""The per-instance memory, end to end on a habit schedule: folded from the log, replayed the same,
asked with ``objsearch where``; and the excess decomposition sums to path − oracle."""

from __future__ import annotations

import json
import uuid
from pathlib import Path
from typing import Any

import pytest

from objsearch.agent.belief import PlaceBelief
from objsearch.agent.catalogue import STORE
from objsearch.agent.memory import InstanceMemory
from objsearch.agent.session import load_context
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import MEMORY, RunSpec
from objsearch.agent.where import LiveMemory, where
from objsearch.cli import main
from objsearch.events.log import EventLog
from objsearch.events.log_read import read_log
from objsearch.events.projection import fold
from objsearch.events.snapshot import restore
from objsearch.experiments.decompose import decompose
from objsearch.sim.longterm import Trial, run_schedule
from objsearch.sim.models import SIM_MODELS
from objsearch.sim.placements import Placement

HOME = "ithor-01"


def _run(log: Path, strategy: str, scenes: tuple[int, ...] = (1, 2, 3)) -> list[Trial]:
    ctx = load_context(HOME)
    spec = RunSpec.for_home(ctx.home, strategy, schedule="habit-0")
    starts = sorted(ctx.home.starts)[:3]
    return run_schedule(
        log, spec, targets=("Cup", "Apple"), scenes=scenes, starts=starts, skip_absent_targets=True
    )


@pytest.fixture(scope="module")
def memory_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Trial]]:
    log = tmp_path_factory.mktemp("memory") / "log"
    return log, _run(log, "ecost-memory")


def test_the_spec_records_the_memory_and_the_fold_rebuilds_it(
    memory_log: tuple[Path, list[Trial]],
) -> None:
    log, trials = memory_log
    assert all(t.success for t in trials)
    state = fold(read_log(log, store=STORE), AgentState())
    assert state.run is not None and state.run.relations.model == "memory"
    assert state.run.method.value == "ecost"
    model = state.graph()
    assert isinstance(model, InstanceMemory)
    assert model.tasks_folded == len(trials)
    again = InstanceMemory.from_snapshot(
        json.loads(json.dumps(model.to_snapshot())), model.last_seq
    )
    assert again.instances("Cup") == model.instances("Cup")


def test_a_place_seen_rises_above_its_class_and_a_miss_falls_below(
    memory_log: tuple[Path, list[Trial]],
) -> None:
    log, _ = memory_log
    model = fold(read_log(log, store=STORE), AgentState()).graph()
    assert isinstance(model, InstanceMemory)
    (d, sid), _ = max(model.seen.items(), key=lambda kv: kv[1])
    cls = model.static_class[sid]
    assert model.instance_rel(d, sid, cls) > model.rel(d, cls)
    missed = [
        (k, v)
        for k, v in sorted(model.missed.items())
        if k not in model.seen and k[1] in model.static_class
    ]
    assert missed
    (d2, sid2), _ = missed[0]
    assert model.instance_rel(d2, sid2, model.static_class[sid2]) < model.rel(
        d2, model.static_class[sid2]
    )


def test_later_searches_of_a_scene_walk_less_than_the_first(
    memory_log: tuple[Path, list[Trial]],
) -> None:
    _, trials = memory_log
    first = [
        t
        for i, t in enumerate(trials)
        if i == 0 or trials[i - 1].target != t.target or trials[i - 1].scene != t.scene
    ]
    later = [t for t in trials if t not in first]

    def excess(ts: list[Trial]) -> float:
        return sum(t.path_length - t.oracle_length for t in ts) / len(ts)

    assert excess(later) < excess(first)


def _unlocated(answer: dict[str, Any]) -> float:
    """Elsewhere's mass when no room holds it (rooms count it when its room is known)."""
    return 0.0 if answer["elsewhere_room"] else float(answer["elsewhere"])


def test_where_answers_from_the_log(
    memory_log: tuple[Path, list[Trial]], capsys: pytest.CaptureFixture[str]
) -> None:
    log, trials = memory_log
    # The time of the latest search (the default, now, may be another slot of the routine).
    assert main(["where", "Cup", str(log), "--format", "json", "--at", "last"]) == 0
    answer = json.loads(capsys.readouterr().out)
    placements: dict[int, dict[str, Placement]] = {}
    from objsearch.sim.longterm import scenes_of

    placements = {k: dict(v) for k, v in scenes_of(HOME, "habit-0").items()}
    last_scene = max(t.scene for t in trials if t.target == "Cup")
    truth = next(p for p in placements[last_scene].values() if p.cls == "Cup")
    assert answer["last_seen"]["static_id"] == truth.support
    assert answer["last_seen"]["room"] == truth.room
    assert answer["most_likely_now"][0]["static_id"] == truth.support
    # Probabilities: the rooms' and an unlocated elsewhere's sum to one, each room's is its
    # places' sum (and elsewhere's, when it was last seen there).
    rooms = {r["room"]: r["probability"] for r in answer["rooms"]}
    assert sum(rooms.values()) + _unlocated(answer) == pytest.approx(1.0, abs=1e-3)
    top = answer["most_likely_now"][0]
    assert rooms[top["room"]] >= top["probability"]
    assert main(["where", "Cup", str(log)]) == 0
    assert "last seen" in capsys.readouterr().out
    assert main(["where", "Unicorn", str(log)]) != 0


def test_where_answers_for_a_time_of_day(
    memory_log: tuple[Path, list[Trial]], capsys: pytest.CaptureFixture[str]
) -> None:
    log, _ = memory_log  # a habit schedule: its scenes are times of day (four a day)
    answers = {}
    for at in ("sat 09:00", "mon 23:30"):
        assert main(["where", "Cup", str(log), "--format", "json", "--at", at]) == 0
        answers[at] = json.loads(capsys.readouterr().out)
    when = answers["sat 09:00"]["time_of_day"]
    assert (when["weekday"], when["minute"], when["slot"]) == (5, 540, "morning/weekend")
    assert answers["mon 23:30"]["time_of_day"]["slot"] == "night/weekday"
    assert sum(when["weights"].values()) == pytest.approx(1.0, abs=1e-3)
    for answer in answers.values():
        rooms = sum(r["probability"] for r in answer["rooms"])
        assert rooms + _unlocated(answer) == pytest.approx(1.0, abs=1e-3)
    assert main(["where", "Cup", str(log)]) == 0
    assert "  at:" in capsys.readouterr().out
    assert main(["where", "Cup", str(log), "--at", "25:00"]) == 2
    assert "expected now, last, HH:MM or DAY HH:MM" in capsys.readouterr().err


def test_excess_decomposition_sums_to_path_minus_oracle(
    memory_log: tuple[Path, list[Trial]],
) -> None:
    log, trials = memory_log
    parts = decompose(read_log(log, store=STORE), load_context(HOME).navmap)
    for t in trials:
        e = parts[t.task_id]
        assert e.start_room <= e.wrong_rooms + 1e-9
        assert e.wrong_rooms + e.right_room(t.oracle_length) + e.approach == pytest.approx(
            t.path_length - t.oracle_length, abs=1e-3
        )


def test_distribution_oracle_is_a_reference_that_runs(tmp_path: Path) -> None:
    trials = _run(tmp_path / "log", "dist-oracle", scenes=(1,))
    assert all(t.success for t in trials)
    state = fold(read_log(tmp_path / "log", store=STORE), AgentState(models=SIM_MODELS))
    assert state.run is not None and state.run.relations.model == "dist-oracle"


def test_a_log_and_the_lake_made_from_it_answer_the_same(
    memory_log: tuple[Path, list[Trial]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log, _ = memory_log
    lake = tmp_path / "lake"
    assert main(["lake", "add", str(log), "--robot", "sim", "--lake", str(lake)]) == 0
    capsys.readouterr()
    answers = []
    for source in ([str(log)], [str(lake)]):
        assert main(["where", "Cup", *source, "--format", "json", "--at", "sat 09:00"]) == 0
        answers.append(json.loads(capsys.readouterr().out))
    assert answers[0] == answers[1]
    assert answers[0]["last_seen"] is not None and answers[0]["run_id"]


def test_where_refuses_what_it_cannot_answer_from(
    memory_log: tuple[Path, list[Trial]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log, _ = memory_log
    lake = tmp_path / "lake"
    lake.mkdir()
    assert main(["where", "Cup", str(lake)]) == 2
    assert "neither an event log (no meta.json) nor a lake" in capsys.readouterr().err
    assert main(["lake", "upgrade", "--lake", str(tmp_path / "empty")]) == 0  # an empty fleet lake
    assert main(["where", "Cup", str(tmp_path / "empty")]) == 2
    assert "holds no runs" in capsys.readouterr().err
    other = tmp_path / "other-log"
    _run(other, "wpl", scenes=(1,))
    for run, source in (("first", log), ("second", other)):
        argv = ["lake", "add", str(source), "--robot", "sim", "--run", run, "--lake", str(lake)]
        assert main(argv) == 0
    capsys.readouterr()
    # Several runs: refused, listing them, rather than guessing which one is meant.
    assert main(["where", "Cup", str(lake)]) == 2
    err = capsys.readouterr().err
    assert "sim/first" in err and "sim/second" in err and "--run" in err
    assert main(["where", "Cup", str(lake), "--run", "second", "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out)["target"] == "Cup"
    assert main(["where", "Cup", str(lake), "--run", "third"]) == 2
    assert "no run 'third'" in capsys.readouterr().err
    assert main(["where", "Unicorn", str(lake), "--run", "first"]) == 2
    assert "unknown object class 'Unicorn'" in capsys.readouterr().err
    # The options it once took still work (with a note): a log or a lake is one positional now.
    assert main(["where", "Cup", "--lake", str(lake), "--run", "second"]) == 0
    assert "--lake is deprecated" in capsys.readouterr().err
    assert main(["where", "Cup", str(log), "--run", "first"]) == 2
    assert main(["where", "Cup", str(tmp_path / "missing")]) == 2
    assert "no such folder" in capsys.readouterr().err


def test_live_memory_restarts_from_its_snapshot_with_the_same_answer(tmp_path: Path) -> None:
    # A wpl run: the memory is a counterfactual fold, which the snapshot must remember.
    log, snapshots = tmp_path / "log", tmp_path / "snapshots"
    _run(log, "wpl", scenes=(1,))
    home = load_context(HOME).home
    full = LiveMemory.restore(log, home, snapshots)
    assert isinstance(full.state.graph(), PlaceBelief)
    full.save(snapshots, log=log)
    again, restored = restore(
        log,
        lambda: AgentState(counterfactual=MEMORY),
        AgentState.from_snapshot,
        snapshot_dir=snapshots,
        save=False,
        store=STORE,
    )
    assert restored.from_snapshot_seq == full.last_seq and restored.rejected is None
    assert isinstance(again.graph(), PlaceBelief)
    from_snapshot = LiveMemory.restore(log, home, snapshots)
    assert (
        from_snapshot.answer("Cup")
        == full.answer("Cup")
        == where(read_log(log, store=STORE), "Cup")
    )
    assert full.answer("Cup")["model_of_run"] == "eq4"


def test_where_remembers_a_sighting_away_from_every_mapped_place(
    memory_log: tuple[Path, list[Trial]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The log's last Cup sighting, moved 1.5 m off its static (``at`` false), as a search that
    found a Cup on the floor records it: ``where`` says so instead of "never" or the old place."""
    log, _ = memory_log
    events = list(read_log(log, store=STORE))
    last = max(
        i
        for i, e in enumerate(events)
        if e.type == "detection" and e.payload["object_class"] == "Cup" and e.payload["accepted"]
    )
    before = where(events, "Cup")
    copy = tmp_path / "log"
    with EventLog.open(copy, "robot", run_id=str(uuid.uuid4()), store=STORE) as writer:
        for i, e in enumerate(events):
            payload = dict(e.payload)
            if i == last:
                x, y, z = payload["position"]
                payload["position"] = [x + 1.5, y, z]
                payload["support"] = {**payload["support"], "at": False}
            writer.append(e.type, payload, time_ns=e.time_ns, task_id=e.task_id)
    answer = where(read_log(copy, store=STORE), "Cup")
    seen = answer["last_seen"]
    assert seen["at"] is False and seen["position"][0] == pytest.approx(
        events[last].payload["position"][0] + 1.5, abs=1e-3
    )
    assert seen["task_id"] == events[last].task_id and seen["room"] is not None
    assert answer["belief_over_places"] > 0
    assert before["last_seen"]["at"] is True
    assert main(["where", "Cup", str(copy)]) == 0
    out = capsys.readouterr().out
    assert "last seen: away from every mapped place" in out
    assert f"probabilities over the {answer['belief_over_places']} places" in out
    # The same answer from the live memory, restored from a snapshot (format 2) of that log.
    home = load_context(HOME).home
    live = LiveMemory.restore(copy, home, tmp_path / "snaps")
    live.save(tmp_path / "snaps", log=copy)
    assert LiveMemory.restore(copy, home, tmp_path / "snaps").answer("Cup") == answer
