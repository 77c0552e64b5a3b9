"""Interop facts, checked against published values (sources in docs/runtime.md)."""

from __future__ import annotations

import math
import time
from typing import Any

import pytest

from objsearch.agent.geometry import Pose
from objsearch.agent.world import Detection
from objsearch.ros.qos import DEFAULT, QoS, Reliability
from objsearch.runtime import messages as m
from objsearch.runtime.errors import MessageError
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


#: A best-effort publisher of ``/qos_fact`` in a process of its own: a dds transport never hears
#: its own participant (runtime/dds_transport.py, ``_qos``).
BEST_EFFORT_PUBLISHER = """
import sys, time
from objsearch.ros.qos import QoS, Reliability
from objsearch.runtime import messages as m
from objsearch.runtime.dds_transport import DdsTransport
from objsearch.runtime.transport import Backend, TransportConfig

t = DdsTransport(TransportConfig(Backend.DDS, domain_id=int(sys.argv[1])))
pub = t.publisher("/qos_fact", m.STRING, QoS(Reliability.BEST_EFFORT))
for _ in range(2400):
    pub.publish(m.encode(m.string("x"), m.STRING))
    time.sleep(0.05)
"""


def test_dds_qos_mismatch_never_matches() -> None:
    """A best-effort writer never meets a reliable reader (ROS 2's QoS compatibility rule)."""
    import os
    import subprocess
    import sys

    from objsearch.runtime.dds_transport import DdsTransport
    from objsearch.runtime.transport import Backend, TransportConfig

    domain = 201 + os.getpid() % 30
    t = DdsTransport(TransportConfig(Backend.DDS, domain_id=domain))
    publisher = subprocess.Popen([sys.executable, "-c", BEST_EFFORT_PUBLISHER, str(domain)])
    try:
        got: dict[str, list[bytes]] = {"reliable": [], "best_effort": []}
        t.subscribe("/qos_fact", m.STRING, DEFAULT, got["reliable"].append)
        t.subscribe("/qos_fact", m.STRING, QoS(Reliability.BEST_EFFORT), got["best_effort"].append)
        deadline = time.monotonic() + 120  # the publisher's interpreter starts first
        while not got["best_effort"] and time.monotonic() < deadline:
            assert publisher.poll() is None, "the publisher exited"
            time.sleep(0.05)
        time.sleep(0.5)  # more of its samples, which the reliable reader must not get either
        assert got["best_effort"] and not got["reliable"]
    finally:
        publisher.kill()
        publisher.wait()
        t.close()


# -- services and actions (sources in docs/runtime.md, "Sources of the interop facts") ----------

#: Published REP-2011 hashes of service and action types (Jazzy): AddTwoInts from rmw_zenoh's
#: design doc; CancelGoal and GoalStatusArray from `ros2 action info -v` output and several
#: client libraries; the Fibonacci action's services from one client library's locked table.
PUBLISHED_SERVICE_HASHES = {
    "action_msgs/srv/CancelGoal": "RIHS01_573d8b0a534451d7bc2ac8c5ffde8ac14b8593b7001175d0cd6516dcbeb8689a",
    "action_msgs/msg/GoalStatusArray": "RIHS01_6c1684b00f177d37438febe6e709fc4e2b0d4248dca4854946f9ed8b30cda83e",
}


def _test_store() -> object:
    from rosbags.typesys import Stores, get_typestore

    from objsearch.runtime import interfaces

    store = get_typestore(Stores.ROS2_HUMBLE)
    b = interfaces._Builder()
    b.add(interfaces._read(interfaces.SERVICE_EVENT_INFO), interfaces.SERVICE_EVENT_INFO)
    b.service("example_interfaces/srv/AddTwoInts", "int64 a\nint64 b\n", "int64 sum\n")
    b.action(
        "action_tutorials_interfaces/action/Fibonacci",
        "int32 order\n",
        "int32[] sequence\n",
        "int32[] partial_sequence\n",
    )
    store.register({k: v for k, v in b.result().items() if k not in store.fielddefs})
    return store


def test_service_and_action_hashes_follow_rosidl() -> None:
    """The expansion rules (request/response/event, action services) give published hashes."""
    store: Any = _test_store()
    assert store.hash_rihs01("example_interfaces/srv/AddTwoInts") == (
        "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"
    )
    fib = "action_tutorials_interfaces/action/Fibonacci"
    assert store.hash_rihs01(f"{fib}_SendGoal") == (
        "RIHS01_a0603060ed69fe2dfbd1a6f3b982a1749957ef346e4a4d2b311a05e305ec37bb"
    )
    assert store.hash_rihs01(f"{fib}_GetResult") == (
        "RIHS01_8b47e383f1e31f6d8df6417ab54957e7d5ea24dad315646ad711ac3fdea81d58"
    )
    assert store.hash_rihs01(f"{fib}_FeedbackMessage") == (
        "RIHS01_50fc26b9cac313652ecbeab3adf9b5414d59fd4d4d5f9058ddcc7525169927f1"
    )
    for name, published in PUBLISHED_SERVICE_HASHES.items():
        assert m.type_hash(name) == published


def test_navigate_to_pose_names() -> None:
    """Computed, not checked against a published value (none exists for Humble's definition)."""
    from objsearch.runtime.action import topics
    from objsearch.runtime.dds_transport import service_topics

    t = topics("/navigate_to_pose")
    srv = "nav2_msgs/action/NavigateToPose_SendGoal"
    assert topic_key(0, t["send_goal"], srv) == (
        "0/navigate_to_pose/_action/send_goal/nav2_msgs::action::dds_::NavigateToPose_SendGoal_/"
        + m.type_hash(srv)
    )
    assert topic_key(0, t["cancel_goal"], "action_msgs/srv/CancelGoal").endswith(
        "/action_msgs::srv::dds_::CancelGoal_/"
        + PUBLISHED_SERVICE_HASHES["action_msgs/srv/CancelGoal"]
    )
    assert service_topics(t["send_goal"]) == (
        "rq/navigate_to_pose/_action/send_goalRequest",
        "rr/navigate_to_pose/_action/send_goalReply",
    )
    # Humble's result is std_msgs/Empty: one byte after the encapsulation.
    result = m.default("nav2_msgs/action/NavigateToPose_Result")
    assert m.encode(result, "nav2_msgs/action/NavigateToPose_Result") == bytes.fromhex("0001000000")


def test_dds_request_header_keeps_the_message_bytes() -> None:
    """cdds_request_header_t (64-bit client id, 64-bit sequence number) leads the sample; the
    declared Cyclone type serialises wrapped requests byte for byte."""
    from objsearch.runtime.action import _goal_info
    from objsearch.runtime.dds_transport import idl_type, unwrap, wrap

    name = "action_msgs/srv/CancelGoal_Request"
    cdr = m.encode(m.types()[name](goal_info=_goal_info(bytes(range(16)), 5)), name)
    data = wrap(cdr, 0x0102030405060708, 42)
    assert data[4:20] == (0x0102030405060708).to_bytes(8, "little") + (42).to_bytes(8, "little")
    assert unwrap(data) == (0x0102030405060708, 42, cdr)
    cls = idl_type(name, request_header=True)
    assert bytes(cls.deserialize(data).serialize()) == data


def test_tf_composes_map_odom_base() -> None:
    """The stand-in's /tf (map → odom offset, odom → base_link) read through the TF buffer gives
    the robot's map pose; odom → base_link alone would not."""
    from objsearch.ros.tf import TransformBuffer

    pose = Pose(2.25, -1.5, 0.75)
    msg = m.decode(m.encode(m.tf(pose, 7_000), m.TF), m.TF)
    buf = TransformBuffer()
    for parent, child, ns, xyz, q in m.transforms_of(msg):
        buf.add(parent, child, ns, xyz, q)
    at = buf.latest_common_ns("map", "base_link")
    assert at == 7_000
    got = m.pose_of_matrix(buf.lookup("map", "base_link", at))
    assert (got.x, got.y) == (pose.x, pose.y) and math.isclose(got.yaw, pose.yaw)
    odom_only = m.pose_of_matrix(buf.lookup("odom", "base_link", at))
    assert (odom_only.x, odom_only.y) != (pose.x, pose.y)


def test_navigation_and_pose_config() -> None:
    from objsearch.runtime.config import RuntimeConfig
    from objsearch.runtime.errors import RuntimeConfigError

    c = RuntimeConfig.from_mapping(
        {
            "navigation": {"interface": "navigate_to_pose", "action": "/r1/navigate_to_pose"},
            "pose": {"source": "tf", "base_frame": "base_footprint"},
        }
    )
    assert c.navigation.action == "/r1/navigate_to_pose" and c.pose.base_frame == "base_footprint"
    with pytest.raises(RuntimeConfigError, match="interface must be goal_pose or navigate_to_pose"):
        RuntimeConfig.from_mapping({"navigation": {"interface": "move_base"}})
    with pytest.raises(RuntimeConfigError, match="source must be odometry or tf"):
        RuntimeConfig.from_mapping({"pose": {"source": "gps"}})
