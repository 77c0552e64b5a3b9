"""The transport seam: topics of CDR bytes with ROS 2 names, types and QoS.

Three backends implement it: :mod:`objsearch.runtime.zenoh_transport` (what ``rmw_zenoh_cpp`` puts
on the wire) and :mod:`objsearch.runtime.dds_transport` (what ``rmw_cyclonedds_cpp`` does), for
robots without ROS 2 installed beside the agent, and :mod:`objsearch.runtime.ros2_transport`, a
real rclpy node on whatever middleware the robot's ROS 2 runs. The
agent's own requests and results (search requests, container openings) are topic pairs with a
correlation id in the JSON body, so they work the same over both; ROS 2 services (Nav2's action)
are request/reply the way each RMW does them.

This module is the seam alone (the types every backend implements and the config); the backends
import it, and :func:`objsearch.runtime.backends.open_transport` picks one, so no import runs back.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from objsearch.ros.qos import QoS
from objsearch.runtime.errors import RuntimeConfigError

#: Called with the CDR bytes of each message, on a middleware thread.
Handler = Callable[[bytes], None]
#: Sends the CDR bytes of a service's response to the request it was handed with.
Responder = Callable[[bytes], None]
#: Called with a request's CDR bytes on a middleware thread; answers through the responder, now
#: or later (an action's get_result is answered when the goal ends), exactly once.
ServiceHandler = Callable[[bytes, Responder], None]


class Publisher(Protocol):
    def publish(self, cdr: bytes) -> None: ...


class ServiceClient(Protocol):
    def call(self, request: bytes, timeout_s: float) -> bytes | None:
        """The response's CDR bytes, or None if none came within ``timeout_s`` (the request is
        sent again while no server is matched, so a call made during discovery still lands)."""
        ...


class Transport(Protocol):
    """One ROS 2 participant (a node's worth of publishers, subscriptions, services, clients).

    A service is named like a topic (``/navigate_to_pose/_action/send_goal``); ``srvtype`` is
    the service type (``nav2_msgs/action/NavigateToPose_SendGoal``), whose ``_Request`` and
    ``_Response`` messages are in the typestore (:mod:`objsearch.runtime.interfaces`).
    """

    def publisher(self, topic: str, msgtype: str, qos: QoS) -> Publisher: ...

    def subscribe(self, topic: str, msgtype: str, qos: QoS, handler: Handler) -> None: ...

    def serve(self, service: str, srvtype: str, handler: ServiceHandler) -> None: ...

    def client(self, service: str, srvtype: str) -> ServiceClient: ...

    def close(self) -> None: ...


class Backend(enum.Enum):
    ZENOH = "zenoh"
    DDS = "dds"
    ROS2 = "ros2"


@dataclass(frozen=True, slots=True)
class TransportConfig:
    """Where the robot's ROS 2 graph is.

    ``domain_id`` is ``ROS_DOMAIN_ID``. Zenoh: ``mode`` peer|client|router, ``connect`` and
    ``listen`` endpoints (rmw_zenoh's default is a peer connecting to its router at
    ``tcp/localhost:7447``). DDS: ``peers`` for unicast discovery and the network ``interface``.
    """

    backend: Backend = Backend.ZENOH
    domain_id: int = 0
    node: str = "objsearch"
    mode: str = "peer"
    connect: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    listen: tuple[str, ...] = ("tcp/127.0.0.1:0",)  # peers listen so gossip can mesh them
    peers: tuple[str, ...] = ("127.0.0.1",)
    interface: str = "lo"
    extra: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not 0 <= self.domain_id <= 232:
            raise RuntimeConfigError(f"ROS domain id must be 0..232, got {self.domain_id}")
        if self.mode not in {"peer", "client", "router"}:
            raise RuntimeConfigError(
                f"zenoh mode must be peer, client or router, not {self.mode!r}"
            )
