"""Interop facts, checked against published values (sources in docs/runtime.md)."""

from __future__ import annotations

import math
import time

import pytest
from objsearch.agent.geometry import Pose
from objsearch.agent.world import Detection
from objsearch.runtime import messages as m
from objsearch.runtime.errors import MessageError
from objsearch.runtime.qos import DEFAULT, QoS, Reliability
from objsearch.runtime.zenoh_transport import (
    attachment,
    liveliness_key,
    parse_attachment,
    topic_key,
)

# REP-2011 hashes as ROS 2 Jazzy's rosidl computes them (see docs/runtime.md, "Sources").
PUBLISHED_HASHES = {
    "std_msgs/msg/String": "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    "geometry_msgs/msg/PoseStamped": "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8",
    "nav_msgs/msg/Odometry": "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
}


@pytest.mark.parametrize("msgtype", sorted(PUBLISHED_HASHES))
def test_type_hash_matches_published(msgtype: str) -> None:
    assert m.type_hash(msgtype) == PUBLISHED_HASHES[msgtype]


def test_dds_type_names() -> None:
    assert m.dds_type_name(m.POSE_STAMPED) == "geometry_msgs::msg::dds_::PoseStamped_"
    assert m.dds_type_name(m.ODOMETRY) == "nav_msgs::msg::dds_::Odometry_"
    assert m.dds_type_name(m.STRING) == "std_msgs::msg::dds_::String_"
    with pytest.raises(MessageError, match="not a ROS 2 type name"):
        m.dds_type_name("Odometry")


def test_dds_topic_names() -> None:
    from objsearch.runtime.dds_transport import topic_name

    assert topic_name("/pose") == "rt/pose"
    assert topic_name("/robot1/cmd_vel") == "rt/robot1/cmd_vel"


def test_rmw_zenoh_key_expressions_match_its_design_doc() -> None:
    chatter = "0/chatter/std_msgs::msg::dds_::String_/" + PUBLISHED_HASHES["std_msgs/msg/String"]
    assert topic_key(0, "/chatter", m.STRING) == chatter
    assert topic_key(0, "/robot1/chatter", m.STRING) == chatter.replace("0/", "0/robot1/", 1)
    token = liveliness_key(
        2,
        "8b20917502ee955ac4476e0266340d5c",
        0,
        10,
        "MP",
        "talker",
        "/chatter",
        m.STRING,
        QoS(depth=7),
    )
    assert token == (
        "@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/"
        "std_msgs::msg::dds_::String_/" + PUBLISHED_HASHES["std_msgs/msg/String"] + "/::,7:,:,:,,"
    )


def test_attachment_layout() -> None:
    gid = bytes(range(16))
    data = attachment(42, 1_700_000_000_123_456_789, gid)
    assert len(data) == 33 and data[:8] == (42).to_bytes(8, "little") and data[16] == 16
    assert parse_attachment(data) == (42, 1_700_000_000_123_456_789, gid)


SAMPLES = [
    (m.STRING, lambda: m.string("hello, robot")),
    (m.POSE_STAMPED, lambda: m.pose_stamped(Pose(1.25, -2.5, 0.75), 1_234_567_890_123)),
    (m.ODOMETRY, lambda: m.odometry(Pose(-3.0, 0.5, -2.0), 42)),
    (
        m.DETECTIONS,
        lambda: m.detections(7, Pose(0, 0, 0), [Detection("Cup", "Cup|1", 900.0, (1.0, 0.5, 0.9))]),
    ),
]


@pytest.mark.parametrize(("msgtype", "make"), SAMPLES, ids=[s[0] for s in SAMPLES])
def test_cyclonedds_bytes_equal_rosbags(msgtype: str, make: object) -> None:
    """What Cyclone DDS serialises for the declared type is byte for byte rosbags' CDR."""
    from objsearch.runtime.dds_transport import idl_type

    msg = make()  # type: ignore[operator]
    cdr = m.encode(msg, msgtype)
    assert cdr[:4] == b"\x00\x01\x00\x00"  # CDR little endian
    assert bytes(idl_type(msgtype).deserialize(cdr).serialize()) == cdr


def test_known_cdr_bytes_of_a_string() -> None:
    # encapsulation, length 3 (with NUL), "hi\0": as a ROS 2 talker publishes it.
    assert m.encode(m.string("hi"), m.STRING) == bytes.fromhex("0001000003000000686900")


def test_pose_and_detections_round_trip() -> None:
    pose = Pose(1.25, -2.5, 0.75)
    back = m.pose_of_odometry(m.decode(m.encode(m.odometry(pose, 5), m.ODOMETRY), m.ODOMETRY))
    assert back.x == pose.x and back.y == pose.y and math.isclose(back.yaw, pose.yaw)
    det = Detection("Cup", "Cup|1", 900.0, (1.0, 0.5, 0.9))
    msg = m.decode(m.encode(m.detections(7, pose, [det]), m.DETECTIONS), m.DETECTIONS)
    (got,) = m.detections_of(msg)
    assert (got.object_class, got.instance_id, got.position) == ("Cup", "Cup|1", (1.0, 0.5, 0.9))
    assert math.isclose(got.mask_area, 900.0)


def test_malformed_bytes_are_a_clear_error() -> None:
    with pytest.raises(MessageError, match="malformed nav_msgs/msg/Odometry"):
        m.decode(b"\x00\x01\x00\x00garbage", m.ODOMETRY)


def test_dds_qos_mismatch_never_matches() -> None:
    """A best-effort writer never meets a reliable reader (ROS 2's QoS compatibility rule)."""
    import os

    from objsearch.runtime.dds_transport import DdsTransport
    from objsearch.runtime.transport import Backend, TransportConfig

    t = DdsTransport(TransportConfig(Backend.DDS, domain_id=201 + os.getpid() % 30))
    try:
        got: dict[str, list[bytes]] = {"reliable": [], "best_effort": []}
        t.subscribe("/qos_fact", m.STRING, DEFAULT, got["reliable"].append)
        t.subscribe("/qos_fact", m.STRING, QoS(Reliability.BEST_EFFORT), got["best_effort"].append)
        pub = t.publisher("/qos_fact", m.STRING, QoS(Reliability.BEST_EFFORT))
        deadline = time.monotonic() + 5
        while not got["best_effort"] and time.monotonic() < deadline:
            pub.publish(m.encode(m.string("x"), m.STRING))
            time.sleep(0.05)
        assert got["best_effort"] and not got["reliable"]
    finally:
        t.close()
