"""Record a simulated run to each format, ingest it, get the agent's own log back."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

from objsearch.events import Event
from objsearch.pipeline.bags.ingest import ingest
from objsearch.pipeline.bags.lake import FleetBagLake
from objsearch.pipeline.bags.read import read_bag

from .bag_fixtures import Recorded


def test_bag_holds_what_a_robot_records(recorded: Recorded) -> None:
    counts = recorded.recording.messages
    assert counts["/tf_static"] == 1
    assert counts["/objsearch/events"] == len(recorded.log)
    assert counts["/odom"] == counts["/tf"] > len(recorded.log) // 4
    assert counts["/objsearch/detections"] == counts["/camera/color/camera_info"] > 0


def test_round_trip_through_the_lake_equals_the_agents_log(
    recorded: Recorded, tmp_path: Path
) -> None:
    [result] = ingest([recorded.bag], tmp_path / "lake")
    assert result.error is None and result.report is not None
    assert result.report.reader == "AnyReader" and not result.report.damaged
    lake_events = list(FleetBagLake(tmp_path / "lake").events())
    agent = sorted((e for e in lake_events if not e.stream.startswith("bag:")), key=lambda e: e.seq)
    # Every field, recorded_at_ns included; time_ns moved onto the bag's clock (one per run).
    offset = result.report.clock_offset_ns
    assert offset == 1_767_225_600_000_000_000  # the recorder's 2026-01-01T00:00Z
    shifted = [
        Event.from_json_dict({**e.to_json_dict(), "time_ns": e.time_ns + offset})
        for e in recorded.log
    ]
    assert agent == shifted
    # Same decisions and path lengths, said the way an analyst would check them.
    ended = [e.payload["path_length"] for e in agent if e.type == "task_ended"]
    assert ended == [e.payload["path_length"] for e in recorded.log if e.type == "task_ended"]
    assert len(ended) == 2
    plans = [
        json.dumps(dict(e.payload), sort_keys=True) for e in agent if e.type == "plan_computed"
    ]
    assert plans == [
        json.dumps(dict(e.payload), sort_keys=True)
        for e in recorded.log
        if e.type == "plan_computed"
    ]
    derived = Counter(e.type for e in lake_events if e.stream.startswith("bag:"))
    assert derived["pose_observed"] == recorded.recording.messages["/odom"]
    assert derived["objects_detected"] == recorded.recording.messages["/objsearch/detections"]


def test_pose_track_follows_the_moves(recorded: Recorded) -> None:
    contents = read_bag(recorded.bag)
    poses = [e for e in contents.events if e.type == "pose_observed"]
    assert {e.payload["frame_id"] for e in poses} == {"map"}
    moved = [e for e in recorded.log if e.type == "moved"]
    track = {(round(e.payload["pose"]["x"], 3), round(e.payload["pose"]["y"], 3)) for e in poses}
    for m in moved:
        end = m.payload["end"]
        assert (round(end["x"], 3), round(end["y"], 3)) in track
    seen = {
        d["instance_id"]
        for e in contents.events
        if e.type == "objects_detected"
        for d in e.payload["detections"]
    }
    assert {e.payload["instance_id"] for e in recorded.log if e.type == "detection"} <= seen


def test_read_is_deterministic(recorded: Recorded) -> None:
    a, b = read_bag(recorded.bag), read_bag(recorded.bag)
    assert a.events == b.events and a.report == b.report
