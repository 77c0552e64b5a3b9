"""The agent's view of one robot: middleware, topics, QoS and patience (``robot.toml``)::

transport = "zenoh"            # or "dds" (both without ROS 2), or "ros2": a real rclpy node
domain_id = 0                  # ROS_DOMAIN_ID
home = "paper"
strategy = "global-belief+cover"  # the default; any of objsearch.agent.strategies, NAME or NAME+cover

[zenoh]
mode = "peer"                  # rmw_zenoh's sessions are peers of a router
connect = ["tcp/192.168.1.20:7447"]   # the robot's rmw_zenohd
listen = []

[dds]
interface = "eth0"
peers = ["192.168.1.20"]

[topics]
goal = "/goal_pose"
odometry = "/odom"
detections = "/objsearch/detections"

[qos]
odometry = "reliable"          # or "best_effort" for a sensor-data publisher

[timeouts]
arrival_s = 60.0

[navigation]
interface = "goal_pose"        # or "navigate_to_pose": Nav2's action (see docs/runtime.md)
action = "/navigate_to_pose"
behavior_tree = ""             # Nav2's default tree
distro = "auto"                # or "humble" / "jazzy": which Nav2's NavigateToPose (see docs)

[pose]
source = "odometry"            # or "tf": map → base_link from /tf and /tf_static
map_frame = "map"
base_frame = "base_link"

[detections]
input = "pose"                 # or "depth" (Detection2DArray + aligned depth) or "3d" (Detection3DArray)
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from objsearch.ros.errors import QosError
from objsearch.ros.qos import DEFAULT, EVENTS, REQUESTS, SENSOR_DATA, TF, TF_STATIC, QoS
from objsearch.runtime.errors import RuntimeConfigError
from objsearch.runtime.transport import Backend, TransportConfig


@dataclass(frozen=True, slots=True)
class Topics:
    goal: str = "/goal_pose"  # geometry_msgs/PoseStamped, as RViz's 2D Goal Pose and Nav2 take it
    odometry: str = "/odom"  # nav_msgs/Odometry, pose in the map frame
    detections: str = "/objsearch/detections"  # vision_msgs/Detection2DArray
    events: str = "/objsearch/events"  # objsearch_msgs/Event, every append
    find: str = "/objsearch/find"  # std_msgs/String JSON {id, target, start?, scene?}
    find_result: str = "/objsearch/find/result"
    where: str = "/objsearch/where"  # std_msgs/String JSON {id, target}: the agent's memory
    where_result: str = "/objsearch/where/result"
    # The typed interfaces a ROS user calls (the JSON topics above stay for clients without ROS 2)
    find_action: str = "/objsearch/find_object"  # objsearch_msgs/action/FindObject
    where_service: str = "/objsearch/where_object"  # objsearch_msgs/srv/Where
    open: str = "/objsearch/open"  # std_msgs/String JSON {id, static_id}
    open_result: str = "/objsearch/open/result"
    sim_reset: str = "/objsearch_sim/reset"  # the stand-in only: {id, scene, start}
    sim_reset_result: str = "/objsearch_sim/reset/result"
    agents: str = "/objsearch/agents"  # std_msgs/String JSON heartbeats: one agent per robot
    tf: str = "/tf"  # tf2_msgs/TFMessage, with [pose] source = "tf"
    tf_static: str = "/tf_static"
    # With [detections] input = "depth" or "3d" (docs/runtime.md): the detector's camera
    camera_info: str = "/camera/color/camera_info"  # sensor_msgs/CameraInfo
    depth: str = "/camera/depth/image_raw"  # sensor_msgs/Image, aligned to the detector's image


@dataclass(frozen=True, slots=True)
class QosSettings:
    odometry: QoS = DEFAULT
    detections: QoS = DEFAULT
    goal: QoS = DEFAULT
    events: QoS = EVENTS
    requests: QoS = REQUESTS  # find, where, open, reset and their results
    tf: QoS = TF
    tf_static: QoS = TF_STATIC
    camera: QoS = SENSOR_DATA  # camera info and depth: best effort meets any camera driver


@dataclass(frozen=True, slots=True)
class Timeouts:
    robot_s: float = 10.0  # no odometry for this long: the robot is gone
    arrival_s: float = 10.0  # a goal not reached in this long is sent again …
    attempts: int = 3  # … up to this many times, then the search fails
    detections_s: float = 5.0  # the camera view after arriving
    tolerance_m: float = 0.05
    tolerance_rad: float = 0.05
    claim_s: float = 5.0  # at start: no other agent of this robot heard for this long → serve


@dataclass(frozen=True, slots=True)
class NavigationSettings:
    """How goals reach the robot: ``goal_pose`` (a PoseStamped topic; arrival judged from the
    pose) or ``navigate_to_pose`` (Nav2's action: arrival is its SUCCEEDED result)."""

    interface: str = "goal_pose"
    action: str = "/navigate_to_pose"
    behavior_tree: str = ""
    #: Which Nav2's NavigateToPose: ``humble`` (result std_msgs/Empty), ``jazzy`` (Jazzy and
    #: later: error_code, error_msg; over --transport ros2), or ``auto``: the server's, read from
    #: the type hash its get_result service shows on the graph (Humble's where the transport
    #: shows none). docs/runtime.md, *Which Nav2*.
    distro: str = "auto"

    def __post_init__(self) -> None:
        if self.interface not in {"goal_pose", "navigate_to_pose"}:
            raise RuntimeConfigError(
                f"[navigation] interface must be goal_pose or navigate_to_pose, "
                f"not {self.interface!r}"
            )
        if self.distro not in {"auto", "humble", "jazzy"}:
            raise RuntimeConfigError(
                f"[navigation] distro must be auto, humble or jazzy, not {self.distro!r}"
            )


@dataclass(frozen=True, slots=True)
class PoseSource:
    """Where the robot's pose in the map comes from: ``odometry`` (its pose in ``map``) or
    ``tf`` (``map_frame`` → ``base_frame`` composed from /tf and /tf_static)."""

    source: str = "odometry"
    map_frame: str = "map"
    base_frame: str = "base_link"

    def __post_init__(self) -> None:
        if self.source not in {"odometry", "tf"}:
            raise RuntimeConfigError(f"[pose] source must be odometry or tf, not {self.source!r}")


@dataclass(frozen=True, slots=True)
class DetectionSettings:
    """How the detector node gives positions (``objsearch.ros.detections``): ``pose`` (a
    Detection2DArray whose hypotheses' pose is the position; the stand-in's default), ``depth``
    (a Detection2DArray back-projected through the aligned depth image) or ``3d`` (a
    Detection3DArray)."""

    input: str = "pose"

    def __post_init__(self) -> None:
        if self.input not in {"pose", "depth", "3d"}:
            raise RuntimeConfigError(
                f"[detections] input must be pose, depth or 3d, not {self.input!r}"
            )


@dataclass(frozen=True, slots=True)
class RuntimeConfig:
    transport: TransportConfig = field(default_factory=TransportConfig)
    home: str = "paper"
    #: None: the product's default (agent/strategies.py DEFAULT_STRATEGY), resolved by the agent
    #: node so that reading a config does not import the agent.
    strategy: str | None = None
    topics: Topics = Topics()
    qos: QosSettings = QosSettings()
    timeouts: Timeouts = Timeouts()
    navigation: NavigationSettings = NavigationSettings()
    pose: PoseSource = PoseSource()
    detections: DetectionSettings = DetectionSettings()

    def check(self) -> None:
        """What no single section can tell: Jazzy's NavigateToPose travels over the ``ros2``
        transport only (rclpy's build of it; the zenoh and dds transports name Humble's)."""
        nav = self.navigation
        if (
            nav.interface == "navigate_to_pose"
            and nav.distro == "jazzy"
            and self.transport.backend is not Backend.ROS2
        ):
            raise RuntimeConfigError(
                "[navigation] distro = 'jazzy' needs --transport ros2: over "
                f"{self.transport.backend.value} only Humble's NavigateToPose is spoken "
                "(docs/runtime.md, the transport x capability matrix)"
            )

    @classmethod
    def load(cls, path: Path) -> RuntimeConfig:
        try:
            doc = tomllib.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise RuntimeConfigError(f"cannot read {path}: {exc.strerror or exc}") from exc
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise RuntimeConfigError(f"{path} is not valid TOML: {exc}") from exc
        return cls.from_mapping(doc, source=str(path))

    @classmethod
    def from_mapping(cls, doc: dict[str, Any], *, source: str = "config") -> RuntimeConfig:
        known = {
            "transport",
            "domain_id",
            "home",
            "strategy",
            "node",
            "zenoh",
            "dds",
            "topics",
            "qos",
            "timeouts",
            "navigation",
            "pose",
            "detections",
        }
        unknown = sorted(set(doc) - known)
        if unknown:
            raise RuntimeConfigError(f"{source}: unknown keys {unknown}; known: {sorted(known)}")
        try:
            backend = Backend(doc.get("transport", "zenoh"))
        except ValueError:
            raise RuntimeConfigError(
                f"{source}: transport must be zenoh, dds or ros2, not {doc['transport']!r}"
            ) from None
        z, d = doc.get("zenoh", {}), doc.get("dds", {})
        base = TransportConfig()
        transport = TransportConfig(
            backend=backend,
            domain_id=int(doc.get("domain_id", 0)),
            node=str(doc.get("node", base.node)),
            mode=str(z.get("mode", base.mode)),
            connect=tuple(z.get("connect", base.connect)),
            listen=tuple(z.get("listen", base.listen)),
            peers=tuple(d.get("peers", base.peers)),
            interface=str(d.get("interface", base.interface)),
        )
        from objsearch.agent.strategies import strategy_names

        strategy = doc.get("strategy")
        if strategy is not None and strategy not in strategy_names():
            raise RuntimeConfigError(
                f"{source}: strategy must be one of {', '.join(strategy_names())}, not {strategy!r}"
            )
        return cls(
            transport=transport,
            home=str(doc.get("home", "paper")),
            strategy=None if strategy is None else str(strategy),
            topics=_section(Topics(), doc.get("topics", {}), source, "topics", str),
            qos=_section(QosSettings(), doc.get("qos", {}), source, "qos", _qos),
            timeouts=_section(Timeouts(), doc.get("timeouts", {}), source, "timeouts", None),
            navigation=_section(
                NavigationSettings(), doc.get("navigation", {}), source, "navigation", str
            ),
            pose=_section(PoseSource(), doc.get("pose", {}), source, "pose", str),
            detections=_section(
                DetectionSettings(), doc.get("detections", {}), source, "detections", str
            ),
        )


def _qos(text: str) -> QoS:
    try:
        return QoS.parse(text)
    except QosError as exc:
        raise RuntimeConfigError(str(exc)) from None


def _section(default: Any, values: dict[str, Any], source: str, name: str, conv: Any) -> Any:
    fields = {f.name: f for f in dataclasses.fields(default)}
    bad = sorted(set(values) - set(fields))
    if bad:
        raise RuntimeConfigError(
            f"{source}: [{name}] has unknown keys {bad}; known: {sorted(fields)}"
        )
    changes = {}
    for key, value in values.items():
        if conv is None:
            kind = type(getattr(default, key))
            if not isinstance(value, int | float) or isinstance(value, bool):
                raise RuntimeConfigError(
                    f"{source}: [{name}] {key} must be a number, not {value!r}"
                )
            changes[key] = kind(value)
        else:
            changes[key] = conv(value)
    return replace(default, **changes)
