"""Schema evolution: old events are upcast on read, and an old log folds to the same graph."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.scene_graph import SceneGraphProjection
from objsearch.agent.session import Session, load_context
from objsearch.agent.strategies import RunSpec
from objsearch.agent.upcasters import STEPS
from objsearch.events import (
    Event,
    EventLog,
    EventStoreError,
    SchemaRegistry,
    Upcaster,
    fold,
    read_log,
)
from objsearch.sim.placements import Schedule
from objsearch.sim.world import SimClock, SimWorld, search_camera

from .payloads import EXAMPLES, LATEST, OLD_EXAMPLES

FIXTURES = Path(__file__).parent / "fixtures"
V1_LOG = FIXTURES / "v1-log"


def test_every_old_version_has_an_upcast_step() -> None:
    registry = STORE.registry
    for event_type in registry.types:
        for version in registry.versions(event_type)[:-1]:
            assert (event_type, version) in STEPS, (event_type, version)


def test_a_missing_step_is_refused(tmp_path: Path) -> None:
    for version in (1, 2):
        schema = {
            "$schema": "https://json-schema.org/draft/2020-12/schema",
            "$id": f"urn:objsearch:events:blip:v{version}",
            "type": "object",
        }
        (tmp_path / f"blip.v{version}.json").write_text(json.dumps(schema))
    with pytest.raises(EventStoreError, match=r"no upcaster for blip v1 → v2"):
        Upcaster(SchemaRegistry.from_directory(tmp_path), {})


@pytest.mark.parametrize("key", sorted(OLD_EXAMPLES))
def test_upcast_payloads_validate_against_the_latest_schema(key: tuple[str, int]) -> None:
    event_type, version = key
    latest, payload = STORE.upcaster.upcast_payload(event_type, version, OLD_EXAMPLES[key])
    assert latest == LATEST[event_type]
    STORE.registry.validate(event_type, latest, payload)
    if event_type == "run_started":  # what the v1 example was: the strategy it named, its spec
        assert {k: v for k, v in payload.items() if k != "params"} == {
            k: v for k, v in EXAMPLES[event_type].items() if k != "params"
        }
        assert payload["params"] == {}
        if version == 1:
            assert OLD_EXAMPLES[key]["params"]["strategy"] == "wpl-neg-decay"  # input unchanged
    elif event_type == "task_started":  # a search before the clock was recorded: unknown time
        assert payload == {**EXAMPLES[event_type], "clock": None}
        assert "clock" not in OLD_EXAMPLES[key]
    else:
        assert payload == EXAMPLES[event_type]
    if key == ("detection", 1):
        assert OLD_EXAMPLES[key]["nearest_static_id"] == "Table|1"  # the input was not changed
    if event_type == "view_taken":  # a view before the tilt was level
        assert payload["pitch"] == 0.0 and "pitch" not in OLD_EXAMPLES[key]


def test_detection_v1_without_a_static_upcasts_to_no_support() -> None:
    old = dict(OLD_EXAMPLES["detection", 1], nearest_static_id=None, nearest_static_class=None)
    old["at_static"] = False
    _, payload = STORE.upcaster.upcast_payload("detection", 1, old)
    assert payload["support"] is None


def test_old_events_are_upcast_on_read_and_kept_as_written_on_disk(tmp_path: Path) -> None:
    with EventLog.open(tmp_path, "s", wall_clock=lambda: 1, store=STORE) as log:
        written = log.append("detection", OLD_EXAMPLES["detection", 1], time_ns=5, version=1)
        log.append("detection", EXAMPLES["detection"], time_ns=6)
    raw = list(read_log(tmp_path, upcast=False, store=STORE))
    assert [(e.version, dict(e.payload)) for e in raw] == [
        (1, OLD_EXAMPLES["detection", 1]),
        (3, EXAMPLES["detection"]),
    ]
    [old, new] = read_log(tmp_path, store=STORE)
    assert old.version == new.version == 3
    assert dict(old.payload) == dict(new.payload) == EXAMPLES["detection"]
    assert (old.event_id, old.seq, old.time_ns) == (written.event_id, 1, 5)
    assert b'"at_static"' in (tmp_path / "events.log").read_bytes()  # never rewritten


# --- the committed v1 log ---------------------------------------------------------------------


def _expected_graph() -> dict[tuple[str, str], float]:
    doc = json.loads((FIXTURES / "v1-log.graph.json").read_text())
    return {(d, s): v for d, s, v in doc["relations"]}


def test_the_fixture_really_holds_version_1_detections() -> None:
    raw = [e for e in read_log(V1_LOG, upcast=False, store=STORE) if e.type == "detection"]
    assert raw and all(e.version == 1 for e in raw)
    assert any(e.payload["at_static"] and e.payload["accepted"] for e in raw)


def test_the_v1_log_reads_as_valid_latest_events() -> None:
    registry = STORE.registry
    for event in read_log(V1_LOG, store=STORE):
        assert event.version == registry.latest_version(event.type)
        registry.validate_event(event)


def test_the_v1_log_folds_to_the_scene_graph_the_v1_code_folded() -> None:
    graph = fold(read_log(V1_LOG, store=STORE), SceneGraphProjection())
    expected = _expected_graph()
    assert graph.relations == expected
    assert graph.tasks_folded == 12
    seeded = next(e for e in read_log(V1_LOG, store=STORE) if e.type == "scene_graph_seeded")
    prior = {(v["dynamic"], v["static"]): v["rel"] for v in seeded.payload["values"]}
    assert sum(abs(expected[k] - prior[k]) for k in prior) > 1.0  # the updates did something


def _rerun_fixture_searches(log_dir: Path) -> None:
    """The searches of fixtures/README.md, with today's code (which writes detection v2)."""
    ctx = load_context("paper")
    # The Table II placements the fixture was recorded with: the schedule has changed since
    # (objects no longer share a spot), and the comparison is of the decisions, not the data.
    schedule = Schedule.load(ctx.home, "table2", FIXTURES / "v1-log.table2.json")
    starts = list(ctx.home.starts.items())
    session = Session.start(ctx, log_dir, RunSpec.for_home(ctx.home, "wpl"))
    try:
        clock = SimClock(session.resume_time_ns)
        for scene in (1, 2):
            for target in ("Cup", "Apple", "Bowl"):
                for start_name, pose in starts[::4]:
                    clock.advance(60.0)
                    # The camera the fixture was recorded with (it predates occlusion).
                    world = SimWorld(
                        ctx.home,
                        ctx.navmap,
                        schedule.scenes[scene],
                        pose,
                        clock=clock,
                        camera=search_camera("geometric"),
                    )
                    session.search(world, target, start_name, scene=scene)
    finally:
        session.close()


def _facts(event: Event) -> dict[str, Any]:
    d = event.to_json_dict()
    del d["recorded_at_ns"]
    return d


def _decision_facts(event: Event) -> dict[str, Any]:
    # The fixture predates the simulated camera's projected-area mask model: the mask areas it
    # measured, and so which detections cleared the threshold, differ. Every plan, move and
    # outcome, and every detection's class, instance, position and support must not.
    # Ids differ by design: a format-1 log derived them from its stream, today's from its run id.
    d = _facts(event)
    del d["event_id"]
    if d["type"] == "run_started":  # today's writer records its log's run id; v1 had none
        d["payload"]["params"].pop("run_id", None)
    if d["type"] == "detection":
        d["payload"] = {k: v for k, v in d["payload"].items() if k not in ("mask_area", "accepted")}
    if d["type"] == "view_taken":  # the fixture predates the camera tilt too (upcast: level)
        d["payload"].pop("pitch")
    return d


def test_todays_code_writes_v2_and_decides_as_the_upcast_v1_log(tmp_path: Path) -> None:
    # A perfect detector's detections are still written as v2 (no score to record: the golden
    # logs stay byte for byte); both logs are compared as read, upcast to the latest version.
    _rerun_fixture_searches(tmp_path / "today")
    raw = list(read_log(tmp_path / "today", upcast=False, store=STORE))
    assert {e.version for e in raw if e.type == "detection"} == {2}
    today = list(read_log(tmp_path / "today", store=STORE))
    old = [_decision_facts(e) for e in read_log(V1_LOG, store=STORE)]
    # target_detected (the paper's metric) is newer than the fixture; without it, and so
    # without the seq numbers it shifts, today's log is the fixture's.
    now = [_decision_facts(e) for e in today if e.type != "target_detected"]
    for d in (*now, *old):
        del d["seq"]
    assert now == old


def test_a_v1_log_can_be_continued_by_todays_writer(tmp_path: Path) -> None:
    log_dir = tmp_path / "continued"
    shutil.copytree(V1_LOG, log_dir)
    with EventLog.open(log_dir, "robot", store=STORE) as log:
        n = log.last_seq
        log.append("detection", EXAMPLES["detection"], time_ns=10**15, task_id="task-99999")
    events = list(read_log(log_dir, store=STORE))
    assert len(events) == n + 1
    assert {e.version for e in events if e.type == "detection"} == {3}
