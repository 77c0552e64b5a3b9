"""The live view's two sinks: a Foxglove WebSocket server and an MCAP file (ROS 2 profile).

They (and :class:`TopicSink`, the same channels as topics of the robot's graph) take the same
:class:`~objsearch.runtime.liveview.LiveMessage` (topic, ROS 2 type, CDR
bytes), so a channel looks the same live and in the file: encoding ``cdr``, schema the type's
``ros2msg`` definition with its dependencies (what ``ros2 bag record`` writes).

* :class:`McapSink` writes with rosbags' own ROS 2 writer (MCAP storage), so the file is a
  rosbag2 MCAP that rosbags' ``Reader``/``AnyReader``, ``ros2 bag`` and Foxglove read. It needs no
  extra package.
* :class:`FoxgloveSink` serves the channels with ``foxglove-sdk`` (the ``robot`` extra) on
  127.0.0.1 unless told otherwise, to clients that offer either name of the protocol,
  ``foxglove.sdk.v1`` or ``foxglove.websocket.v1`` (:mod:`objsearch.runtime.wsfront`). A client that subscribes late gets the channel's last message
  again, so the map (sent once) is there whenever Foxglove connects.
"""

from __future__ import annotations

import logging
import shutil
import tempfile
import threading
from pathlib import Path
from typing import Any

from objsearch.agent.errors import ObjsearchError
from objsearch.runtime import messages as m
from objsearch.runtime.liveview import LiveMessage
from objsearch.runtime.transport import Publisher, Transport
from objsearch.runtime.wsfront import FrontLimits, FrontStats, SubprotocolFront

log = logging.getLogger("objsearch.liveview")

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765


class LiveViewError(ObjsearchError):
    """The live view cannot start: the port is taken, the file cannot be written, …"""


def parse_address(text: str) -> tuple[str, int]:
    """``PORT``, ``HOST:PORT`` or ``[IPv6]:PORT`` → (host, port); the host defaults to loopback."""
    host, sep, port_text = text.rpartition(":")
    if not sep:
        host = DEFAULT_HOST
    elif host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    elif not host or ":" in host:
        raise LiveViewError(f"--live {text!r}: expected PORT or HOST:PORT (IPv6 as [addr]:PORT)")
    try:
        port = int(port_text)
    except ValueError:
        raise LiveViewError(f"--live {text!r}: the port {port_text!r} is not a number") from None
    if not 0 <= port <= 65535:
        raise LiveViewError(f"--live {text!r}: the port must be 0–65535 (0 picks a free one)")
    return host, port


def channel_qos(topic: str) -> Any:
    """The QoS a live channel is recorded with: the map and the statics latched (sent once,
    as a map server does), the event stream as the agent's, the rest rclcpp's default."""
    from objsearch.ros import bagqos
    from objsearch.runtime import liveview as lv

    if topic in (lv.MAP, lv.STATICS):
        return bagqos.LATCHED
    return bagqos.EVENTS if topic == lv.EVENTS else bagqos.DEFAULT


class McapSink:
    """A rosbag2 MCAP file at ``path`` (``*.mcap``), complete once :meth:`close` returns:
    zstd chunks with CRCs unless ``compress`` is false, each channel with its QoS.

    rosbags writes a bag directory (``NAME/NAME.mcap`` + ``metadata.yaml``); it lives in a hidden
    sibling ``.NAME.mcap.*`` while the view runs and its ``.mcap`` is renamed to ``path`` on close,
    so ``path`` never holds a file without its summary. After a crash the partial file stays in
    that hidden folder (its chunks are readable; the summary is missing).
    """

    def __init__(self, path: Path, *, compress: bool = True) -> None:
        from rosbags.rosbag2 import StoragePlugin, WriterError

        from objsearch.ros.mcapstore import rosbag2_writer

        if path.suffix != ".mcap":
            raise LiveViewError(f"the live view's MCAP file must end in .mcap; got {path}")
        if path.exists():
            raise LiveViewError(f"{path} already exists; choose a new file (never overwritten)")
        self.path = path
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._tmp_root = Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=path.parent))
        except OSError as exc:
            raise LiveViewError(
                f"cannot write the MCAP file {path}: {exc.strerror or exc}"
            ) from exc
        self._bag = self._tmp_root / path.stem
        self._writer = rosbag2_writer(self._bag, StoragePlugin.MCAP, compress=compress)
        try:
            self._writer.open()
        except (WriterError, OSError) as exc:
            shutil.rmtree(self._tmp_root, ignore_errors=True)
            raise LiveViewError(f"cannot write the MCAP file {path}: {exc}") from exc
        self._connections: dict[str, Any] = {}
        self.counts: dict[str, int] = {}
        self._closed = False

    def write(self, message: LiveMessage) -> None:
        conn = self._connections.get(message.topic)
        if conn is None:
            conn = self._writer.add_connection(
                message.topic,
                message.msgtype,
                typestore=m.store(),
                offered_qos_profiles=[channel_qos(message.topic)],
            )
            self._connections[message.topic] = conn
        self._writer.write(conn, message.stamp_ns, message.data)
        self.counts[message.topic] = self.counts.get(message.topic, 0) + 1

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.close()
            (self._bag / f"{self._bag.name}.mcap").rename(self.path)
        except OSError as exc:
            raise LiveViewError(
                f"could not finish the MCAP file {self.path}: {exc.strerror or exc} "
                f"(what was written is in {self._tmp_root})"
            ) from exc
        shutil.rmtree(self._tmp_root, ignore_errors=True)

    def abort(self) -> None:
        """Drop what was written: ``path`` is not created (a replay that failed half way)."""
        from rosbags.rosbag2 import WriterError

        if not self._closed:
            self._closed = True
            try:
                self._writer.close()
            except (WriterError, OSError) as exc:  # dropped all the same
                log.warning("live view: dropping %s: %s", self.path, exc)
        shutil.rmtree(self._tmp_root, ignore_errors=True)


class FoxgloveSink:
    """A Foxglove WebSocket server (``foxglove-sdk``) with one channel per live topic.

    ``limits`` bounds what clients may cost (:class:`~objsearch.runtime.wsfront.FrontLimits`:
    how many at once, how much may wait for one, how long a handshake may take); a client over
    them is refused or dropped, never the agent.
    """

    def __init__(
        self,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        *,
        name: str = "objsearch",
        limits: FrontLimits | None = None,
    ) -> None:
        try:
            import foxglove
            from foxglove.websocket import ServerListener
        except ImportError:
            raise LiveViewError(
                "the live view needs foxglove-sdk: pip install 'objsearch[robot]' "
                "(or pip install foxglove-sdk)"
            ) from None
        self._foxglove = foxglove
        # A context of our own: the SDK's global one would mix in any other user of the library.
        self._context = foxglove.Context()
        self._channels: dict[str, Any] = {}
        self._latest: dict[int, bytes] = {}
        self._lock = threading.Lock()
        sink = self

        class Latch(ServerListener):
            """Re-sends a channel's last message to a client that subscribes (called from the
            SDK's thread): the map and the statics are sent once, long before Foxglove connects."""

            def on_subscribe(self, client: Any, channel: Any) -> None:
                sink._resend(int(channel.id))

        # The SDK listens on a loopback port of its own behind a front door that also accepts
        # the protocol's earlier name, which Foxglove's published client offers (wsfront.py).
        try:
            self._server = foxglove.start_server(
                name=name,
                host="127.0.0.1",
                port=0,
                context=self._context,
                server_listener=Latch(),
            )
        except RuntimeError as exc:
            raise LiveViewError(f"cannot start the live view's Foxglove server: {exc}") from exc
        try:
            self._front = SubprotocolFront(host, port, int(self._server.port), limits)
        except OSError as exc:
            self._server.stop()
            raise LiveViewError(
                f"cannot serve the live view on {host}:{port}: {exc.strerror or exc} "
                "(choose another port with --live HOST:PORT, or 0 for a free one)"
            ) from exc
        self.host = host
        self.port = self._front.port

    @property
    def limits(self) -> FrontLimits:
        return self._front.limits

    def stats(self) -> FrontStats:
        """What the front door holds and has refused or dropped (connections, queues)."""
        return self._front.stats()

    def write(self, message: LiveMessage) -> None:
        with self._lock:
            channel = self._channels.get(message.topic)
            if channel is None:
                channel = self._channel(message)
                self._channels[message.topic] = channel
            self._latest[channel.id()] = message.data
        # Stamped on arrival (the SDK's default): a live viewer orders by when things happen.
        channel.log(message.data)

    def _channel(self, message: LiveMessage) -> Any:
        definition, _ = m.store().generate_msgdef(message.msgtype, ros_version=2)
        schema = self._foxglove.Schema(
            name=message.msgtype, encoding="ros2msg", data=definition.encode("utf-8")
        )
        return self._foxglove.Channel(
            message.topic, schema=schema, message_encoding="cdr", context=self._context
        )

    def _resend(self, channel_id: int) -> None:
        with self._lock:
            data = self._latest.get(channel_id)
            channel = next((c for c in self._channels.values() if c.id() == channel_id), None)
        if data is not None and channel is not None:
            channel.log(data)

    def close(self) -> None:
        self._front.close()
        try:
            self._server.stop()
        except RuntimeError as exc:  # already stopped
            log.debug("live view: the Foxglove server: %s", exc)


class TopicSink:
    """The live channels as topics of the robot's own graph, published by the agent's node:
    readable by any ROS 2 node and RViz2 (``runtime/rviz/objsearch.rviz``) with the standard
    types. The map and the statics are latched (transient local, depth 1), so a viewer that
    starts late still gets them; the events as the agent's event stream; the rest default."""

    def __init__(self, transport: Transport) -> None:
        self._transport = transport
        self._publishers: dict[str, Publisher] = {}
        self.counts: dict[str, int] = {}

    def write(self, message: LiveMessage) -> None:
        from objsearch.ros import qos
        from objsearch.runtime import liveview as lv

        publisher = self._publishers.get(message.topic)
        if publisher is None:
            profile = (
                qos.LATCHED
                if message.topic in (lv.MAP, lv.STATICS)
                else qos.EVENTS
                if message.topic == lv.EVENTS
                else qos.DEFAULT
            )
            publisher = self._transport.publisher(message.topic, message.msgtype, profile)
            self._publishers[message.topic] = publisher
        publisher.publish(message.data)
        self.counts[message.topic] = self.counts.get(message.topic, 0) + 1

    def close(self) -> None:
        """The publishers go with the node (the transport is the agent's)."""
        self._publishers.clear()
