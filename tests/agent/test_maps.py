"""Map identity (agent/maps.py): every session runs in a map, evidence carries the map it was
gathered in, and ``where`` (the log's and the live agent's) gives its age and map and flags an
answer resting on a map the robot has left."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.home import load_home
from objsearch.agent.maps import DEFAULT_MAP, map_of, next_map
from objsearch.agent.session import load_context
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import RunSpec
from objsearch.agent.where import LiveMemory, memory_state, render, where
from objsearch.cli import main
from objsearch.events.log_read import read_log
from objsearch.sim.longterm import run_schedule

TARGETS = ("Apple", "Cup", "Vase")


def test_map_ids() -> None:
    assert map_of({}) == DEFAULT_MAP == "map-0"
    assert map_of({"map": "map-3"}) == "map-3"
    assert next_map("map-0") == "map-1"
    assert next_map("map-9") == "map-10"
    assert next_map("attic") == "attic-1"


def _search(log: Path, target: str, scene: int, *extra: str) -> None:
    args = ["search", target, "--start", "kitchen-1", "--scene", str(scene), "--log", str(log)]
    assert main([*args, *extra, "--format", "json"]) in (0, 1)


def _answer(log: Path, target: str) -> dict[str, object]:
    return where(read_log(log, store=STORE), target)


def test_where_flags_every_answer_resting_on_a_map_the_robot_left(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "log"
    for scene, target in enumerate(TARGETS, start=1):
        _search(log, target, scene)
    before = {t: _answer(log, t) for t in TARGETS}
    for t, a in before.items():
        maps = a["map"]
        assert isinstance(maps, dict)
        assert maps["current"] == "map-0" and not maps["flagged"], t
        assert maps["evidence"] and all(e["map"] == "map-0" for e in maps["evidence"])
    _search(log, "Apple", 4, "--new-map")
    state = memory_state(read_log(log, store=STORE))
    assert state.maps.current == "map-1" and state.maps.left() == ["map-0"]
    for t in TARGETS:
        a = _answer(log, t)
        maps = a["map"]
        assert isinstance(maps, dict)
        # Every class with a sighting in map-0 rests on it: flagged, and said so.
        assert maps["current"] == "map-1" and maps["flagged"], t
        assert "map-0" in maps["flag"]
        old = next(e for e in maps["evidence"] if e["map"] == "map-0")
        assert old["sightings"] >= 1 and old["age_s"] > 0 and not old["current"]
    # A later session without --new-map stays in the map it is in.
    _search(log, "Cup", 5)
    assert memory_state(read_log(log, store=STORE)).maps.current == "map-1"
    # The search's own summary names the map it ran in.
    capsys.readouterr()
    _search(log, "Vase", 6)
    assert json.loads(capsys.readouterr().out)["map"] == "map-1"


def test_where_text_and_json_give_age_and_map(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "log"
    _search(log, "Apple", 1)
    _search(log, "Cup", 2)
    capsys.readouterr()
    assert main(["where", "Apple", str(log), "--at", "last", "--format", "json"]) == 0
    answer = json.loads(capsys.readouterr().out)
    last = answer["last_seen"]
    assert last["map"] == "map-0" and not last["map_left"] and last["age_s"] > 0
    assert answer["map"]["current"] == "map-0" and answer["map"]["flag"] is None
    assert main(["where", "Apple", str(log), "--at", "last"]) == 0
    text = capsys.readouterr().out
    assert " ago in map-0" in text and "  map:       now map-0; evidence map-0 (now):" in text
    assert "FLAGGED" not in text
    _search(log, "Cup", 3, "--new-map")
    capsys.readouterr()
    assert main(["where", "Apple", str(log), "--at", "last"]) == 0
    text = capsys.readouterr().out
    assert "a map the robot has left" in text and "FLAGGED:   rests on evidence from map-0" in text
    assert render(_answer(log, "Apple")) == text.rstrip("\n")


def test_the_live_agent_answers_the_same_and_its_snapshot_keeps_the_maps(tmp_path: Path) -> None:
    log = tmp_path / "log"
    _search(log, "Apple", 1)
    _search(log, "Cup", 2, "--new-map")
    live = LiveMemory.restore(log, load_home("paper"), tmp_path / "snap")
    answer = live.answer("Apple")
    assert answer["map"]["flagged"] and answer["map"] == _answer(log, "Apple")["map"]
    state = live.state
    again = AgentState.from_snapshot(state.to_snapshot(), state.last_seq)
    assert again.maps == state.maps


def test_a_schedule_changes_map_on_its_day(tmp_path: Path) -> None:
    ctx = load_context("paper")
    spec = RunSpec.of("paper", ctx.home.digest, "wpl", schedule="table2", params={"new_map_day": 2})
    run_schedule(tmp_path / "log", spec, targets=("Apple",), scenes=(1, 2), starts=("kitchen-1",))
    events = list(read_log(tmp_path / "log", store=STORE))
    started = [e for e in events if e.type == "run_started"]
    assert [map_of(e.payload["params"]) for e in started] == ["map-0", "map-1"]
    # The second session starts before the first search of scene 2.
    first_of_day_2 = next(e for e in events if e.type == "task_started" and e.payload["scene"] == 2)
    assert started[1].seq < first_of_day_2.seq
    maps = _answer(tmp_path / "log", "Apple")["map"]
    assert isinstance(maps, dict) and maps["flagged"]


def test_one_detection_handler_folds_the_experience_and_the_evidence_as_the_two_do() -> None:
    """The agent's state folds a detection record into its Eq. 4 experience and its map
    evidence in one call: the same as the two handlers one after the other, before any map
    (nothing counted in the evidence), for rejected and accepted detections, at a static or
    not, with and without one."""
    from types import SimpleNamespace

    from objsearch.agent.maps import MapEvidence
    from objsearch.agent.task_experience import TaskExperience

    def record(seq: int, cls: str, accepted: bool, support: object) -> SimpleNamespace:
        payload = SimpleNamespace(object_class=cls, accepted=accepted, support=support)
        return SimpleNamespace(seq=seq, time_ns=seq * 10, task_id=f"task-{seq:05d}",
                               payload=payload)  # fmt: skip

    at_sink = SimpleNamespace(static_id="Sink|1", static_class="Sink", at=True)
    near_bed = SimpleNamespace(static_id="Bed|1", static_class="Bed", at=False)
    records = [
        record(1, "Cup", True, at_sink),  # before any map: experience only
        record(2, "Cup", True, near_bed),
        record(3, "Apple", False, at_sink),
        record(4, "Apple", True, None),
        record(5, "Cup", True, at_sink),
        record(6, "Vase", True, near_bed),
    ]
    ends = []
    for fused in (True, False):
        maps, task = MapEvidence(), TaskExperience()
        task.start("Cup")
        if fused:
            handlers = [maps.record_handlers(task)["detection"]]
        else:
            handlers = [task.record_handler(), maps.record_handlers()["detection"]]
        for r in records:
            if r.seq == 2:
                maps.current = DEFAULT_MAP
            for handler in handlers:
                handler(r)
        ends.append((maps.to_snapshot(), task.seen_at_rows()))
    assert ends[0] == ends[1]
    assert ends[0][1] == {"Apple": [], "Cup": ["Sink"], "Vase": []}
    assert ends[0][0]["by_class"]["Cup"] == {DEFAULT_MAP: [2, 50, "task-00005"]}
