"""The pose track built as columns: the same table as an event per pose, the same decisions as
the per-message rules, whichever decoder read the bytes."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.geometry import Pose
from objsearch.events.arrow import events_to_tables
from objsearch.pipeline.bags import posetrack
from objsearch.pipeline.bags.converter import Converter
from objsearch.pipeline.bags.read import BagContents, read_bag
from objsearch.pipeline.bags.salvage import RawConnection
from objsearch.ros.builder import MessageBuilder
from objsearch.ros.topics import TopicMap
from objsearch.ros.types import Distro, typestore

from .bag_fixtures import Recorded


def _assert_tables_are_the_events_tables(contents: BagContents) -> None:
    fast = contents.tables()
    general = events_to_tables(contents.events, STORE)
    assert list(fast) == list(general)
    for event_type, table in general.items():
        assert fast[event_type].schema.equals(table.schema, check_metadata=True), event_type
        assert fast[event_type].equals(table), event_type


def test_tables_from_columns_equal_the_tables_of_the_events(recorded: Recorded) -> None:
    contents = read_bag(recorded.bag)
    assert len(contents.poses) == recorded.recording.messages["/odom"]
    _assert_tables_are_the_events_tables(contents)


def _shared(shared_bags: Path) -> list[Path]:
    return sorted(
        p
        for p in shared_bags.glob("*/*")
        if p.suffix == ".bag" or (p.is_dir() and (p / "metadata.yaml").exists())
    )


def test_tables_from_columns_on_the_real_bags(shared_bags: Path, tmp_path: Path) -> None:
    bags = _shared(shared_bags)
    assert len(bags) >= 11
    poses = 0
    for bag in bags:
        contents = read_bag(bag)
        _assert_tables_are_the_events_tables(contents)
        poses += len(contents.poses)
    config = tmp_path / "topics.toml"
    config.write_text('[topics]\n"/base_pose_ground_truth" = "odometry"\n', encoding="utf-8")
    contents = read_bag(shared_bags / "embag" / "test.bag", TopicMap.load(config))
    _assert_tables_are_the_events_tables(contents)
    assert poses + len(contents.poses) > 0


EDGES = [
    0.0,
    -0.0,
    1e5,
    -1e5,
    math.nextafter(1e5, math.inf),
    -math.nextafter(1e5, math.inf),
    math.inf,
    -math.inf,
    math.nan,
    1e308,
]


def test_the_vector_checks_are_the_scalar_rules() -> None:
    def scalar_ok(rule: Any, *args: float) -> bool:
        try:
            rule(*args)
        except ValueError:
            return False
        return True

    values = np.array(EDGES)
    with np.errstate(all="ignore"):
        masks = posetrack._implausible(values)
    assert masks.tolist() == [not scalar_ok(posetrack.coord, v) for v in EDGES]
    w = [
        1.0,
        1.0 + 1e-3,
        math.nextafter(1.0 + 1e-3, 2.0),
        1.0 - 1e-3,
        math.nextafter(1.0 - 1e-3, 0.0),
        0.0,
        math.inf,
        math.nan,
        1e200,
    ]
    quats = [(0.0, 0.0, 0.0, v) for v in w] + [(0.5, 0.5, 0.5, 0.5), (0.6, 0.0, 0.8, 1e-2)]
    cols = [np.array(c) for c in zip(*quats, strict=True)]
    with np.errstate(all="ignore"):
        masks = posetrack._not_rotation(*cols)
    assert masks.tolist() == [not scalar_ok(posetrack.rotation_norm, *q) for q in quats]


# -- a synthetic ROS 2 bag's messages, fed straight into the converter --------------------------

ODOM = RawConnection(1, "/odom", "nav_msgs/msg/Odometry", "", "")
TF = RawConnection(2, "/tf", "tf2_msgs/msg/TFMessage", "", "")


def _messages() -> list[tuple[RawConnection, int, Any]]:
    """Odometry and TF with every case the rules tell apart."""
    m = MessageBuilder(Distro.ROS2, TopicMap())
    t = 1_700_000_000 * 10**9
    out: list[tuple[RawConnection, int, Any]] = []
    for i in range(40):
        pose = Pose(0.1 * i, -0.05 * i, 0.07 * i)
        out.append((ODOM, t + i * 10**8, m.odometry(t + i * 10**8, pose, (0.1, 0.0))))
        # map → odom moves now and then; TF and odometry share stamps (ties in arrival order)
        tf = m.tf(t + i * 10**8, pose)
        tf.transforms[0].transform.translation.x = float(i // 10)
        out.append((TF, t + i * 10**8, tf))
    odom = m.odometry(t + 5, Pose(1.0, 2.0, 0.3), (0.0, 0.0))
    odom.pose.pose.position.x = math.nan
    out.append((ODOM, t + 5, odom))
    odom = m.odometry(t + 6, Pose(1.0, 2.0, 0.3), (0.0, 0.0))
    odom.pose.pose.orientation = m._rotation((0.0, 0.0, 0.0, 2.0))
    out.append((ODOM, t + 6, odom))
    for frame in ("", "/odom", "map"):
        odom = m.odometry(t + 7, Pose(3.0, 1.0, -0.2), (0.0, 0.0))
        odom.header.frame_id = frame
        out.append((ODOM, t + 7, odom))
    # A good odom → base transform, then one with a bad rotation: the first counts, the
    # message is rejected.
    tf = m.tf(t + 8, Pose(4.0, 4.0, 1.0))
    tf.transforms[0] = tf.transforms[1]
    tf.transforms[1] = m._transform(t + 8, "base_link", "x", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.5))
    out.append((TF, t + 8, tf))
    tf = m.tf(t + 9, Pose(1e6, 0.0, 0.0))
    out.append((TF, t + 9, tf))
    return out


def _convert(messages: list[tuple[RawConnection, int, Any]], little_endian: bool) -> Converter:
    store = typestore(Distro.ROS2)
    conv = Converter(TopicMap(), "ab" * 32, Distro.ROS2)
    conv.plan(dict.fromkeys(conn for conn, _, _ in messages), lambda c: None)
    for conn, stamp, msg in messages:
        raw = bytes(store.serialize_cdr(msg, conn.msgtype, little_endian=little_endian))
        conv.feed(conn.id, stamp, raw, store.deserialize_cdr)
    conv.end_of_messages()
    return conv


@pytest.mark.parametrize("odometry", [True, False], ids=["odometry", "tf-only"])
def test_byte_decoders_and_rosbags_give_the_same_track(odometry: bool) -> None:
    messages = [m for m in _messages() if odometry or m[0] is TF]
    # Big-endian CDR is not in the byte decoders' layouts: rosbags deserialises every message.
    fast, slow = _convert(messages, True), _convert(messages, False)
    a, b = fast.finish(), slow.finish()
    assert a.poses.table("s").equals(b.poses.table("s"))
    assert [(s.events, s.rejected) for s in fast.topics.values()] == [
        (s.events, s.rejected) for s in slow.topics.values()
    ]
    assert (fast.start_ns, fast.end_ns) == (slow.start_ns, slow.end_ns)
    tf = fast.topics[TF.id]
    assert sorted(tf.rejected) == [
        "ValueError: coordinate 1000000.0 is not plausible",
        "ValueError: quaternion of norm 0.5 is not a rotation",
    ]
    table = a.poses.table("s")
    if odometry:
        assert sorted(fast.topics[ODOM.id].rejected) == [
            "ValueError: coordinate nan is not plausible",
            "ValueError: quaternion of norm 2 is not a rotation",
        ]
        assert table.num_rows == 43  # the 40 + 3 good odometry messages; TF poses dropped
        assert set(table["topic"].to_pylist()) == {"/odom"}
    else:
        # 40 poses from TF, plus the good transform before the bad one (the message is rejected).
        assert table.num_rows == 41 and tf.events == 40
    assert set(table["frame_id"].to_pylist()) == {"map"}  # composed with map → odom


def test_poses_follow_the_map_to_odom_track_as_of_their_time() -> None:
    conv = _convert([m for m in _messages() if m[0] is TF][:40], True)
    done = conv.finish()
    table = done.poses.table("s")
    poses = table["pose"].to_pylist()
    for i, pose in enumerate(poses):
        # map → odom is (i // 10, 0, 0) with no rotation; odom → base is the recorded pose
        assert pose["x"] == pytest.approx(0.1 * i + i // 10)
        assert pose["y"] == pytest.approx(-0.05 * i)
        assert pose["yaw"] == pytest.approx(0.07 * i)
    assert table["seq"].to_pylist() == list(range(1, 41))
    assert isinstance(table, pa.Table)
