"""The agent as a node of the robot's own ROS 2, through rclpy.

Whatever middleware the robot's ROS 2 runs (``RMW_IMPLEMENTATION``; the ``ros2`` extra installs
Fast DDS, Jazzy's default) carries the same CDR bytes the other transports move: topics are
published and taken *raw* (rclpy serialises nothing), so the message layer above the seam is
unchanged. Services — and so Nav2's ``navigate_to_pose`` action, whose goal, result and cancel
are services — go through rclpy's own clients and servers, converted at the seam with
``rclpy.serialization``. The node is visible to every ROS 2 tool (``ros2 node list``,
``get_node_names_and_namespaces``), with the types' RIHS01 hashes that rosidl computed.

rclpy is imported only here, when this transport is chosen, in a process started with the ROS
environment (:mod:`objsearch.runtime.ros2_env`). The Python classes of the
interfaces without a wheel come from :mod:`objsearch.runtime.ros2_types`.

Discovery: ``interface = "lo"`` (the default) keeps the node on this host
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) unless that variable is set; another interface
leaves ROS 2's default (the subnet). ``peers`` other than 127.0.0.1 become ``ROS_STATIC_PEERS``.
"""

from __future__ import annotations

import importlib
import logging
import os
import threading
import time
from collections.abc import Callable
from typing import Any

from objsearch.ros.qos import Durability, QoS, Reliability
from objsearch.ros.untrusted import attempt
from objsearch.runtime.errors import MessageError, TransportError
from objsearch.runtime.transport import Handler, ServiceHandler, TransportConfig

log = logging.getLogger("objsearch.runtime")

#: rclpy executor threads: a service whose answer comes later (an action's get_result, answered
#: when the goal ends) holds one until then.
THREADS = 16
#: The longest a service request waits for its handler's answer before the node gives up on it.
ANSWER_S = 3600.0
#: An action's parts, as the typestore names them (``pkg/action/Name_Part``), in rclpy's classes.
_ACTION_PARTS = {
    "SendGoal": "SendGoalService",
    "GetResult": "GetResultService",
    "FeedbackMessage": "FeedbackMessage",
}


def interface(typename: str) -> Any:
    """``pkg/msg/Name``, ``pkg/srv/Name`` or ``pkg/action/Name[_Part]`` → the rclpy class. A
    typestore alias of another distro's definition (``interfaces.WIRE_NAMES``: Jazzy's
    ``NavigateToPose``) is the wire's class from that distro's build, which this process then
    uses for good (``ros2_types.activate``)."""
    from objsearch.runtime import ros2_types
    from objsearch.runtime.interfaces import WIRE_NAMES

    try:
        pkg, kind, name = typename.split("/")
    except ValueError:
        raise MessageError(f"not a ROS 2 type name: {typename!r}") from None
    variant = ""
    for alias, (wire, which) in WIRE_NAMES.items():
        leaf, wire_leaf = alias.rsplit("/", 1)[1], wire.rsplit("/", 1)[1]
        if typename.startswith(alias.rsplit("/", 1)[0] + "/") and (
            name == leaf or name.startswith(leaf + "_")
        ):
            name, variant = wire_leaf + name[len(leaf) :], which
            break
    if pkg == "nav2_msgs":
        ros2_types.activate(pkg, variant)
    try:
        module = importlib.import_module(f"{pkg}.{kind}")
    except ImportError as exc:
        raise TransportError(
            f"no Python type support for {typename} ({exc}); the interfaces without a wheel are "
            "built by `python -m objsearch.runtime.ros2_types` (make .venv/.installed does it)"
        ) from None
    part = None
    if kind == "action" and "_" in name:
        name, part = name.rsplit("_", 1)
    try:
        cls = getattr(module, name)
        if part is not None:
            impl = _ACTION_PARTS.get(part)
            cls = getattr(cls.Impl, impl) if impl else getattr(cls, part)
    except AttributeError:
        raise MessageError(f"{pkg}.{kind} has no type {typename!r}") from None
    return cls


def qos_profile(qos: QoS) -> Any:
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=qos.depth,
        reliability=ReliabilityPolicy.RELIABLE
        if qos.reliability is Reliability.RELIABLE
        else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL
        if qos.durability is Durability.TRANSIENT_LOCAL
        else DurabilityPolicy.VOLATILE,
    )


def _describe(qos: QoS) -> str:
    return f"{qos.reliability.value}, {qos.durability.value}, depth {qos.depth}"


def _on_incompatible(
    side: str, topic: str, qos: QoS, report: Callable[[str, str], None] | None = None
) -> Any:
    """``report(topic, text)``: told of each mismatch too (the agent names it in its answers)."""
    peer = "a writer offers" if side == "reader" else "a reader requests"

    def callback(event: Any) -> None:
        if event.total_count_change <= 0:
            return
        policy = getattr(event.last_policy_kind, "name", str(event.last_policy_kind))
        text = (
            f"QoS mismatch on {topic}: {peer} QoS this {side} ({_describe(qos)}) cannot match: "
            f"{policy.removeprefix('RMW_QOS_POLICY_').lower().replace('_', ' ')} differs "
            f"({event.total_count} incompatible so "
            "far); nothing flows between them"
        )
        log.warning("%s", text)
        if report is not None:
            report(topic, text)

    return callback


def _discovery_environment(config: TransportConfig) -> str:
    """Set ROS 2's discovery variables from the config where the user has not; says what."""
    if "ROS_AUTOMATIC_DISCOVERY_RANGE" not in os.environ and config.interface in {
        "lo",
        "127.0.0.1",
    }:
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    peers = [p for p in config.peers if p not in {"127.0.0.1", "localhost"}]
    if peers and "ROS_STATIC_PEERS" not in os.environ:
        os.environ["ROS_STATIC_PEERS"] = ";".join(peers)
    scope = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET (ROS 2's default)")
    static = os.environ.get("ROS_STATIC_PEERS")
    return f"discovery range {scope}" + (f", static peers {static}" if static else "")


class _Ros2Publisher:
    def __init__(self, publisher: Any, msgtype: str) -> None:
        self._publisher = publisher
        self._msgtype = msgtype

    def publish(self, cdr: bytes) -> None:
        self._publisher.publish(bytes(cdr))


class _Ros2Client:
    def __init__(self, transport: Ros2Transport, service: str, srvtype: str) -> None:
        self._cls = interface(srvtype)
        self._client = transport.node.create_client(
            self._cls, service, callback_group=transport._group
        )

    def call(self, request: bytes, timeout_s: float) -> bytes | None:
        from rclpy.serialization import deserialize_message, serialize_message

        deadline = time.monotonic() + timeout_s
        message = attempt(lambda: deserialize_message(request, self._cls.Request))
        if isinstance(message, Exception):
            raise MessageError(f"cannot send a malformed request: {message}") from None
        if not self._client.wait_for_service(timeout_sec=max(0.0, deadline - time.monotonic())):
            return None
        future = self._client.call_async(message)
        done = threading.Event()
        future.add_done_callback(lambda _: done.set())
        if not done.wait(max(0.0, deadline - time.monotonic())) and not future.done():
            self._client.remove_pending_request(future)
            return None
        return bytes(serialize_message(future.result()))


class Ros2Transport:
    """One rclpy node (its own context, so several can live in one process) spun by a
    multi-threaded executor on a thread of its own."""

    def __init__(self, config: TransportConfig) -> None:
        try:
            import rclpy
            from rclpy.callback_groups import ReentrantCallbackGroup
            from rclpy.executors import MultiThreadedExecutor
        except ImportError as exc:
            from objsearch.runtime import ros2_env

            if ros2_env.library_dirs() and not ros2_env.ready():
                raise TransportError(
                    "rclpy cannot load its libraries: this process was started without them on "
                    "LD_LIBRARY_PATH; start it under `python -m objsearch.runtime.ros2_env "
                    "COMMAND` (objsearch's own commands restart themselves so)"
                ) from exc
            raise TransportError(
                f"the ros2 transport needs rclpy ({exc}): pip install 'objsearch[ros2]'"
            ) from exc
        from rclpy.context import Context
        from rclpy.exceptions import NameValidationException
        from rclpy.utilities import get_rmw_implementation_identifier

        self.config = config
        scope = _discovery_environment(config)
        self._context = Context()
        try:
            rclpy.init(context=self._context, domain_id=config.domain_id)
            self.node: Any = rclpy.create_node(
                config.node,
                context=self._context,
                start_parameter_services=False,
            )
        # rclpy's RCLError (and its kinds) is a RuntimeError; a bad node name a NameValidationException
        except (RuntimeError, ValueError, NameValidationException) as exc:
            raise TransportError(
                f"cannot start a ROS 2 node in domain {config.domain_id}: {exc}"
            ) from exc
        self._group = ReentrantCallbackGroup()
        self._closed = threading.Event()
        #: The latest QoS mismatch on each topic (text as logged), for the agent's answers.
        self.qos_mismatches: dict[str, str] = {}
        self._executor = MultiThreadedExecutor(num_threads=THREADS, context=self._context)
        self._executor.add_node(self.node)
        self._spinner = threading.Thread(target=self._spin, name="ros2-executor", daemon=True)
        self._spinner.start()
        self.rmw = get_rmw_implementation_identifier()
        log.info(
            "joined ROS 2 domain %d (ROS_DOMAIN_ID) through %s as node %s; %s",
            config.domain_id,
            self.rmw,
            self.node.get_fully_qualified_name(),
            scope,
        )

    def _spin(self) -> None:
        from rclpy.executors import ExternalShutdownException

        try:
            self._executor.spin()
        except ExternalShutdownException:
            pass
        except RuntimeError:  # rclpy's InvalidHandle is one
            # Closing on a loaded machine: the executor's shutdown timed out with a spin still in
            # progress, and the node it was waiting on is gone (rclpy's InvalidHandle). Nothing is
            # lost at that point; any other time it is a real error.
            if not self._closed.is_set():
                raise

    def publisher(self, topic: str, msgtype: str, qos: QoS) -> _Ros2Publisher:
        from rclpy.event_handler import PublisherEventCallbacks

        publisher = self.node.create_publisher(
            interface(msgtype),
            topic,
            qos_profile(qos),
            event_callbacks=PublisherEventCallbacks(
                incompatible_qos=_on_incompatible("writer", topic, qos, self._mismatch)
            ),
        )
        return _Ros2Publisher(publisher, msgtype)

    def subscribe(self, topic: str, msgtype: str, qos: QoS, handler: Handler) -> None:
        from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
        from rclpy.event_handler import SubscriptionEventCallbacks

        # One group per subscription: its messages are handled one at a time, in order.
        self.node.create_subscription(
            interface(msgtype),
            topic,
            lambda data: handler(bytes(data)),
            qos_profile(qos),
            callback_group=MutuallyExclusiveCallbackGroup(),
            event_callbacks=SubscriptionEventCallbacks(
                incompatible_qos=_on_incompatible("reader", topic, qos, self._mismatch)
            ),
            raw=True,
        )

    def serve(self, service: str, srvtype: str, handler: ServiceHandler) -> None:
        from rclpy.serialization import deserialize_message, serialize_message

        cls = interface(srvtype)

        def callback(request: Any, response: Any) -> Any:
            answer: list[bytes] = []
            answered = threading.Event()

            def respond(cdr: bytes) -> None:
                answer.append(cdr)
                answered.set()

            handler(bytes(serialize_message(request)), respond)
            deadline = time.monotonic() + ANSWER_S
            while not answered.wait(0.5):
                if self._closed.is_set() or time.monotonic() > deadline:
                    log.warning("%s: a request went unanswered", service)
                    return response
            return deserialize_message(answer[0], cls.Response)

        self.node.create_service(cls, service, callback, callback_group=self._group)

    def client(self, service: str, srvtype: str) -> _Ros2Client:
        return _Ros2Client(self, service, srvtype)

    def _mismatch(self, topic: str, text: str) -> None:
        self.qos_mismatches[topic] = text

    def publisher_types(self, topic: str) -> list[tuple[str, str]]:
        """``(node, type)`` of every publisher of ``topic`` the graph shows."""
        infos = self.node.get_publishers_info_by_topic(topic)
        return sorted(
            {(f"{i.node_namespace.rstrip('/')}/{i.node_name}", str(i.topic_type)) for i in infos}
        )

    def service_type_hashes(self, service: str) -> list[str]:
        """The RIHS01 hashes the graph shows for the servers of ``service``: the type hash each
        server's reply writer carries (that of the service's ``_Response``; ``rr/<service>Reply``
        under ROS 2's DDS name mangling)."""
        infos = self.node.get_publishers_info_by_topic(f"rr{service}Reply", no_mangle=True)
        return sorted({str(i.topic_type_hash) for i in infos})

    def close(self) -> None:
        if self._closed.is_set():
            return
        self._closed.set()
        self._executor.shutdown(timeout_sec=5.0)
        # The spin ends before its node goes (destroying a node under a spin breaks the spin).
        self._spinner.join(5.0)
        self.node.destroy_node()
        self._context.try_shutdown()
