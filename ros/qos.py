"""ROS 2 quality of service, as far as the agent's topics need it, and rmw_zenoh's key form."""

from __future__ import annotations

import enum
from dataclasses import dataclass

from objsearch.ros.errors import QosError


class Reliability(enum.Enum):
    RELIABLE = "reliable"
    BEST_EFFORT = "best_effort"


class Durability(enum.Enum):
    VOLATILE = "volatile"
    TRANSIENT_LOCAL = "transient_local"


@dataclass(frozen=True, slots=True)
class QoS:
    """KEEP_LAST history of ``depth`` (KEEP_ALL is not needed by the agent)."""

    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    depth: int = 10

    def __post_init__(self) -> None:
        if self.depth < 1:
            raise QosError(f"QoS depth must be >= 1, got {self.depth}")

    @classmethod
    def parse(cls, text: str) -> QoS:
        """``reliable``, ``best_effort,transient_local``, ``reliable,volatile,5`` …"""
        rel, dur, depth = Reliability.RELIABLE, Durability.VOLATILE, 10
        for part in filter(None, (p.strip() for p in text.split(","))):
            if part.isdigit():
                depth = int(part)
            elif part in {r.value for r in Reliability}:
                rel = Reliability(part)
            elif part in {d.value for d in Durability}:
                dur = Durability(part)
            else:
                raise QosError(
                    f"unknown QoS setting {part!r} in {text!r}; use reliable|best_effort, "
                    "volatile|transient_local and a depth"
                )
        return cls(rel, dur, depth)

    def zenoh_key(self) -> str:
        """rmw_zenoh's compact QoS chunk of a liveliness token (``qos_to_keyexpr``):
        ``<reliability>:<durability>:<history>,<depth>:<deadline>:<lifespan>:<liveliness>``,
        ROS 2 defaults left empty; enum values are rmw's (reliable 1, best effort 2;
        transient local 1, volatile 2; keep last 1)."""
        rel = "" if self.reliability is Reliability.RELIABLE else "2"
        dur = "" if self.durability is Durability.VOLATILE else "1"
        return f"{rel}:{dur}:,{self.depth}:,:,:,,"


#: The ROS 2 profiles the agent's topics use.
DEFAULT = QoS()
SENSOR_DATA = QoS(Reliability.BEST_EFFORT, Durability.VOLATILE, 5)
LATCHED = QoS(Reliability.RELIABLE, Durability.TRANSIENT_LOCAL, 1)
EVENTS = QoS(Reliability.RELIABLE, Durability.VOLATILE, 1000)
#: The agent's request and result topics (find, where, open, reset): a reader must hold a burst
#: until it is taken, and rclpy's executor takes one message per callback, much slower than a
#: burst arrives, so ROS 2's default depth of 10 dropped requests (issue 43). The depth is
#: offered and requested alike and is not matched between peers, so any client still meets it.
REQUESTS = QoS(Reliability.RELIABLE, Durability.VOLATILE, 1000)
#: rmw_qos_profile_services_default.
SERVICES = QoS(Reliability.RELIABLE, Durability.VOLATILE, 10)
#: rcl_action's status topic (rcl_action_qos_profile_status_default): latched.
ACTION_STATUS = QoS(Reliability.RELIABLE, Durability.TRANSIENT_LOCAL, 1)
#: tf2_ros: a TransformListener's /tf and the latched /tf_static.
TF = QoS(Reliability.RELIABLE, Durability.VOLATILE, 100)
TF_STATIC = QoS(Reliability.RELIABLE, Durability.TRANSIENT_LOCAL, 1)
