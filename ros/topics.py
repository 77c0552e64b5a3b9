"""The topic map: which topic carries what, and which message types each role accepts.

The defaults are what ``objsearch record`` writes and what the robot publishes. A site whose
robot names things differently overrides them with a TOML or JSON file::

    [topics]
    "/odometry/filtered" = "odometry"
    "/odom" = "ignore"          # drop a default

    [frames]
    map = "map"
    odom = "odom"
    base = "base_link"
    camera = "camera_link"
    camera_optical = "camera_link_optical"
"""

from __future__ import annotations

import enum
import json
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any, Final

from objsearch.ros.errors import TopicMapError


class Role(enum.Enum):
    """What a topic is for. Only some roles become events; the rest are known but not converted."""

    ODOMETRY = "odometry"
    TF = "tf"
    TF_STATIC = "tf_static"
    CAMERA_INFO = "camera_info"
    IMAGE = "image"
    DEPTH = "depth"
    INSTANCES = "instances"
    DETECTIONS = "detections"
    EVENTS = "events"


#: Message types (rosbags' ROS 2 style names; ROS 1 names are normalised to these) each role reads.
ACCEPTED_TYPES: Final[Mapping[Role, frozenset[str]]] = MappingProxyType(
    {
        Role.ODOMETRY: frozenset({"nav_msgs/msg/Odometry"}),
        Role.TF: frozenset({"tf2_msgs/msg/TFMessage", "tf/msg/tfMessage"}),
        Role.TF_STATIC: frozenset({"tf2_msgs/msg/TFMessage", "tf/msg/tfMessage"}),
        Role.CAMERA_INFO: frozenset({"sensor_msgs/msg/CameraInfo"}),
        Role.IMAGE: frozenset({"sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"}),
        Role.DEPTH: frozenset({"sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"}),
        Role.INSTANCES: frozenset({"sensor_msgs/msg/Image"}),
        Role.DETECTIONS: frozenset({"vision_msgs/msg/Detection2DArray"}),
        Role.EVENTS: frozenset({"objsearch_msgs/msg/Event"}),
    }
)

#: Roles turned into events. Camera info and images are recognised and counted, not converted
#: into events: ``objsearch map build --bag`` reads them (``rgbd.py``).
CONVERTED: Final = frozenset({Role.ODOMETRY, Role.TF, Role.TF_STATIC, Role.DETECTIONS, Role.EVENTS})

DEFAULT_TOPICS: Final[Mapping[str, Role]] = MappingProxyType(
    {
        "/odom": Role.ODOMETRY,
        "/tf": Role.TF,
        "/tf_static": Role.TF_STATIC,
        "/camera/color/camera_info": Role.CAMERA_INFO,
        "/camera/color/image_raw": Role.IMAGE,
        "/camera/depth/image_raw": Role.DEPTH,
        "/camera/instances/image_raw": Role.INSTANCES,
        "/objsearch/detections": Role.DETECTIONS,
        "/objsearch/events": Role.EVENTS,
    }
)

IGNORE: Final = "ignore"


@dataclass(frozen=True, slots=True)
class Frames:
    """TF frame names (REP-105): map → odom → base → camera → camera_optical.

    ``camera`` follows the body convention (x forward, z up); images and camera info are in
    ``camera_optical`` (REP-103's ``_optical`` suffix: x right, y down, z forward)."""

    map: str = "map"
    odom: str = "odom"
    base: str = "base_link"
    camera: str = "camera_link"
    camera_optical: str = "camera_link_optical"


@dataclass(frozen=True, slots=True)
class TopicMap:
    # A plain dict (treat it as read-only): a mapping proxy would not pickle to worker processes.
    topics: Mapping[str, Role] = field(default_factory=lambda: dict(DEFAULT_TOPICS))
    frames: Frames = Frames()

    def role(self, topic: str) -> Role | None:
        return self.topics.get(topic)

    def topic_for(self, role: Role) -> str:
        """The first topic mapped to ``role`` (what ``record`` writes)."""
        for topic, r in self.topics.items():
            if r is role:
                return topic
        raise TopicMapError(f"the topic map has no topic for role {role.value!r}")

    @classmethod
    def load(cls, path: Path) -> TopicMap:
        """The defaults overridden by a ``.toml`` or ``.json`` file (see the module docstring)."""
        try:
            raw = path.read_bytes()
        except OSError as exc:
            raise TopicMapError(f"cannot read topic map {path}: {exc.strerror or exc}") from exc
        try:
            doc = json.loads(raw) if path.suffix == ".json" else tomllib.loads(raw.decode("utf-8"))
        except (ValueError, UnicodeDecodeError) as exc:
            raise TopicMapError(
                f"topic map {path} is not valid {path.suffix[1:] or 'TOML'}: {exc}"
            ) from exc
        return cls.from_mapping(doc, source=str(path))

    @classmethod
    def from_mapping(cls, doc: Any, *, source: str = "topic map") -> TopicMap:
        if not isinstance(doc, dict):
            raise TopicMapError(f"{source}: expected a table/object at the top")
        unknown = sorted(set(doc) - {"topics", "frames"})
        if unknown:
            raise TopicMapError(f"{source}: unknown section(s) {unknown}; expected topics, frames")
        topics = dict(DEFAULT_TOPICS)
        roles = {r.value: r for r in Role}
        for topic, role in dict(doc.get("topics", {})).items():
            if not (isinstance(topic, str) and topic.startswith("/")):
                raise TopicMapError(f"{source}: topic {topic!r} must be a string starting with '/'")
            if role == IGNORE:
                topics.pop(topic, None)
            elif role in roles:
                topics[topic] = roles[role]
            else:
                raise TopicMapError(
                    f"{source}: topic {topic!r} has unknown role {role!r}; "
                    f"known: {', '.join([*roles, IGNORE])}"
                )
        frames_doc = doc.get("frames", {})
        if not isinstance(frames_doc, dict):
            raise TopicMapError(f"{source}: frames must be a table/object")
        known = set(Frames.__dataclass_fields__)
        bad = sorted(set(frames_doc) - known)
        if bad or not all(isinstance(v, str) and v for v in frames_doc.values()):
            raise TopicMapError(
                f"{source}: frames takes non-empty strings for {sorted(known)}; got {frames_doc!r}"
            )
        return cls(topics=topics, frames=replace(Frames(), **frames_doc))
