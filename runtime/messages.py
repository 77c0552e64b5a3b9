"""The one message layer both transports share: rosbags' ROS 2 types, CDR bytes, ROS 2 names.

The types are the ROS 2 Humble store plus the repository's own ``.msg`` definitions
(``objsearch.ros.types``), and events and detections are built by ``objsearch.ros.builder``, so
they travel as the same ``objsearch_msgs/msg/Event`` and ``vision_msgs/msg/Detection2DArray`` the
bag pipeline records.
A backend only ever moves the CDR bytes :func:`encode` returns; the names and hashes each
middleware needs come from here.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from functools import cache
from typing import TYPE_CHECKING, Any

from objsearch.agent.geometry import Pose
from objsearch.agent.world import Detection
from objsearch.events import Event
from objsearch.ros.builder import DEFAULT_BOX_CAMERA, BoxCamera, MessageBuilder
from objsearch.ros.topics import TopicMap
from objsearch.ros.types import Distro, typestore
from objsearch.ros.untrusted import attempt
from objsearch.runtime.errors import MessageError

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
ODOMETRY = "nav_msgs/msg/Odometry"
STRING = "std_msgs/msg/String"
DETECTIONS = "vision_msgs/msg/Detection2DArray"
EVENT = "objsearch_msgs/msg/Event"
TF = "tf2_msgs/msg/TFMessage"
GOAL_STATUS_ARRAY = "action_msgs/msg/GoalStatusArray"


@cache
def store() -> Typestore:
    """The bag pipeline's ROS 2 store plus the services and actions of :mod:`interfaces`."""
    from objsearch.runtime import interfaces

    ts = typestore(Distro.ROS2)
    interfaces.register(ts)
    return ts


def types() -> Any:
    return store().types


def dds_type_name(msgtype: str) -> str:
    """``geometry_msgs/msg/PoseStamped`` → ``geometry_msgs::msg::dds_::PoseStamped_`` (rosidl's
    DDS name, which both rmw_cyclonedds_cpp and rmw_zenoh_cpp use)."""
    parts = msgtype.split("/")
    if len(parts) != 3 or not all(parts):
        raise MessageError(f"{msgtype!r} is not a ROS 2 type name like pkg/msg/Name")
    pkg, kind, name = parts
    return f"{pkg}::{kind}::dds_::{name}_"


@cache
def type_hash(msgtype: str) -> str:
    """The REP-2011 type description hash, ``RIHS01_<sha256 hex>``."""
    try:
        return str(store().hash_rihs01(msgtype))
    except KeyError:
        raise MessageError(f"unknown message type {msgtype!r}") from None


def encode(msg: Any, msgtype: str) -> bytes:
    """CDR (little endian, with its 4-byte encapsulation header), as ROS 2 puts on the wire."""
    return bytes(store().serialize_cdr(msg, msgtype))


#: The encapsulation headers of plain CDR, big and little endian (what ROS 2 sends).
CDR_HEADERS = (b"\x00\x00", b"\x00\x01")


def decode(data: bytes, msgtype: str) -> Any:
    if data[:2] not in CDR_HEADERS or len(data) < 4:
        raise MessageError(f"malformed {msgtype} ({len(data)} bytes): not plain CDR")
    message = attempt(lambda: store().deserialize_cdr(data, msgtype))
    if isinstance(message, Exception):  # rosbags raises assorted errors on short or garbled bytes
        raise MessageError(f"malformed {msgtype} ({len(data)} bytes): {message}") from None
    return message


# -- builders and readers for what the agent and the robot exchange ----------------------------


def stamp(ns: int) -> Any:
    return types()["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)


def stamp_ns(header: Any) -> int:
    return int(header.stamp.sec) * 10**9 + int(header.stamp.nanosec)


def header(ns: int, frame: str = "map") -> Any:
    return types()["std_msgs/msg/Header"](stamp=stamp(ns), frame_id=frame)


def _pose_msg(pose: Pose) -> Any:
    t = types()
    return t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=float(pose.x), y=float(pose.y), z=0.0),
        orientation=t["geometry_msgs/msg/Quaternion"](
            x=0.0, y=0.0, z=math.sin(pose.yaw / 2), w=math.cos(pose.yaw / 2)
        ),
    )


def _pose_of(msg: Any) -> Pose:
    p, q = msg.position, msg.orientation
    values = (p.x, p.y, q.x, q.y, q.z, q.w)
    if not all(math.isfinite(v) for v in values):
        raise MessageError(f"pose with non-finite values {values}")
    yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
    return Pose(float(p.x), float(p.y), yaw)


def pose_stamped(pose: Pose, ns: int, frame: str = "map") -> Any:
    return types()[POSE_STAMPED](header=header(ns, frame), pose=_pose_msg(pose))


def pose_of_pose_stamped(msg: Any) -> Pose:
    return _pose_of(msg.pose)


def odometry(pose: Pose, ns: int, frame: str = "map", child: str = "base_link") -> Any:
    import numpy as np

    t = types()
    zero3 = t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    return t[ODOMETRY](
        header=header(ns, frame),
        child_frame_id=child,
        pose=t["geometry_msgs/msg/PoseWithCovariance"](
            pose=_pose_msg(pose), covariance=np.zeros(36, dtype=np.float64)
        ),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t["geometry_msgs/msg/Twist"](linear=zero3, angular=zero3),
            covariance=np.zeros(36, dtype=np.float64),
        ),
    )


def pose_of_odometry(msg: Any) -> Pose:
    return _pose_of(msg.pose.pose)


def string(data: str) -> Any:
    return types()[STRING](data=data)


def json_string(doc: dict[str, Any]) -> Any:
    return string(json.dumps(doc, sort_keys=True, separators=(",", ":")))


def detections(
    ns: int, pose: Pose, dets: Sequence[Detection], camera: BoxCamera = DEFAULT_BOX_CAMERA
) -> Any:
    """The bag pipeline's encoding (``objsearch record``): class and instance in the hypothesis
    and id, the 3-D position (map frame) as the hypothesis pose, the mask area as the box area
    (drawn in ``camera``)."""
    return MessageBuilder(Distro.ROS2, TopicMap(), camera).detections(ns, pose, dets)


def detections_of(msg: Any) -> tuple[Detection, ...]:
    """A ``Detection2DArray`` whose hypotheses' poses are map-frame positions (what
    :func:`detections` builds), read by the one converter (``objsearch.ros.detections``)."""
    import numpy as np

    from objsearch.ros.detections import DetectionError, from_pose_2d

    try:
        return from_pose_2d(msg, np.eye(4))
    except DetectionError as exc:
        raise MessageError(str(exc)) from None


def event(e: Event, ns: int) -> Any:
    return MessageBuilder(Distro.ROS2, TopicMap()).event(ns, e)


# -- TF: what the stand-in publishes and how the agent reads map → base_link --------------------

#: The stand-in's map → odom: a fixed offset (as a localiser's correction), so a reader that
#: skipped the composition would be visibly wrong. Dyadic numbers keep the sums exact.
MAP_TO_ODOM = (1.0, -0.5)


def tf(pose: Pose, ns: int, frames: tuple[str, str, str] = ("map", "odom", "base_link")) -> Any:
    """map → odom (:data:`MAP_TO_ODOM`) and odom → base_link, at one stamp."""
    t = types()
    world, odom, base = frames
    ox, oy = MAP_TO_ODOM

    def transform(parent: str, child: str, x: float, y: float, yaw: float) -> Any:
        return t["geometry_msgs/msg/TransformStamped"](
            header=header(ns, parent),
            child_frame_id=child,
            transform=t["geometry_msgs/msg/Transform"](
                translation=t["geometry_msgs/msg/Vector3"](x=x, y=y, z=0.0),
                rotation=_pose_msg(Pose(0.0, 0.0, yaw)).orientation,
            ),
        )

    return t[TF](
        transforms=[
            transform(world, odom, ox, oy, 0.0),
            transform(odom, base, pose.x - ox, pose.y - oy, pose.yaw),
        ]
    )


def transforms_of(msg: Any) -> list[tuple[str, str, int, Any, Any]]:
    """``(parent, child, stamp, translation xyz, rotation xyzw)`` of each transform."""
    import numpy as np

    out = []
    for tr in msg.transforms:
        v, q = tr.transform.translation, tr.transform.rotation
        out.append(
            (
                str(tr.header.frame_id).lstrip("/"),
                str(tr.child_frame_id).lstrip("/"),
                stamp_ns(tr.header),
                np.array([v.x, v.y, v.z], dtype=np.float64),
                np.array([q.x, q.y, q.z, q.w], dtype=np.float64),
            )
        )
    return out


def pose_of_matrix(matrix: Any) -> Pose:
    """A 4×4 transform (map ← base) as the robot's planar pose."""
    x, y = float(matrix[0, 3]), float(matrix[1, 3])
    yaw = math.atan2(float(matrix[1, 0]), float(matrix[0, 0]))
    if not all(math.isfinite(v) for v in (x, y, yaw)):
        raise MessageError(f"transform with non-finite values {(x, y, yaw)}")
    return Pose(x, y, yaw)


def default(msgtype: str) -> Any:
    """A message with every field at its ROS 2 default (zero, empty, nested defaults), as a
    ``NavigateToPose_Result`` an action server returns when it has nothing to say."""
    import numpy as np
    from rosbags.interfaces import Nodetype

    def value(node: Any) -> Any:
        kind, detail = node
        if kind == Nodetype.BASE:
            name = detail[0]
            if name.startswith("float"):
                return 0.0
            return "" if name == "string" else False if name == "bool" else 0
        if kind == Nodetype.NAME:
            return default(detail)
        if kind == Nodetype.ARRAY:
            sub, length = detail
            if sub[0] == Nodetype.BASE and sub[1][0] not in {"string", "bool"}:
                return np.zeros(length, dtype=np.dtype(_NUMPY.get(sub[1][0], sub[1][0])))
            return [value(sub) for _ in range(length)]
        return [] if kind == Nodetype.SEQUENCE else None

    _, fields = store().fielddefs[msgtype]
    return types()[msgtype](**{name: value(node) for name, node in fields})


_NUMPY = {"byte": "uint8", "char": "uint8"}
