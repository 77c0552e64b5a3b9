"""A seeded battery of hostile WebSocket clients against the live view, while it draws a log.

The live view (:class:`~objsearch.runtime.livesinks.FoxgloveSink` behind the front door of
:mod:`objsearch.runtime.wsfront`) serves a probe viewer subscribed to the event channel while an
"agent" thread draws a real log on it over and over. Meanwhile rounds of hostile connections,
each of a seeded random kind, come and go:

* ``drip``: a valid handshake, one byte per tick, never finished in time;
* ``silent``: connects and says nothing;
* ``junk``: random bytes ending in a blank line; ``oversize``: a head longer than 64 KiB;
  ``plain``: an HTTP request that is no WebSocket upgrade; ``subprotocol``: an unknown one;
* ``holder``: a valid client that holds its place (over the cap it must get HTTP 503);
* ``nonreader``: a valid client that subscribes to every channel and never reads again;
* ``hangup``: half a handshake, then it closes; ``reset``: a client that subscribes, reads a
  little, then resets the connection.

Each connection gets one verdict: ``clear error`` (refused with an HTTP status and a reason, or
closed by the server, which counted and logged why: timeout, eviction, too slow), ``unchanged``
(a valid client served as any other, or a client that left and whose place was freed),
``traceback`` (the front door logged an exception), ``silent change`` (a bad handshake upgraded,
a connection held past every deadline, a place never freed, more connections held than the
cap), ``loss`` (for the probe: a message it did not get, or a round after which a fresh viewer
could not connect). ``tests/runtime/test_wsflood.py`` and ``benchmarks/ws_flood.py`` run it.
"""

from __future__ import annotations

import base64
import contextlib
import json
import logging
import os
import random
import socket
import struct
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Final

from objsearch.agent.session import load_context
from objsearch.events import Event
from objsearch.runtime import liveview as lv
from objsearch.runtime.livesinks import FoxgloveSink
from objsearch.runtime.wsfront import SDK_SUBPROTOCOL, FrontLimits, FrontStats

KINDS: Final = (
    "drip",
    "silent",
    "junk",
    "oversize",
    "plain",
    "subprotocol",
    "holder",
    "nonreader",
    "hangup",
    "reset",
)
#: Kinds whose handshake is valid: the server upgrades them (or answers 503 at the cap).
VALID: Final = frozenset({"holder", "nonreader", "reset"})
COLUMNS: Final = ("tried", "clear error", "unchanged", "traceback", "silent change", "loss")
#: Seconds any single wait of the battery may take before it counts as a failure.
DEADLINE_S: Final = 120.0


def closed_by_server(sock: socket.socket) -> bool:
    """True once the server has ended ``sock`` (EOF or reset); reads nothing else."""
    try:
        return sock.recv(65536, socket.MSG_DONTWAIT) == b""
    except BlockingIOError:
        return False
    except OSError:
        return True


def handshake(subprotocol: str | None = SDK_SUBPROTOCOL) -> bytes:
    key = base64.b64encode(os.urandom(16)).decode()
    return (
        f"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
        + (f"Sec-WebSocket-Protocol: {subprotocol}\r\n" if subprotocol else "")
        + "\r\n"
    ).encode()


class Viewer:
    """A minimal blocking Foxglove client (RFC 6455 client side, unfragmented frames)."""

    def __init__(self, port: int, *, rcvbuf: int | None = None) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        if rcvbuf is not None:  # before connecting, so the window is small from the start
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        self.sock.settimeout(DEADLINE_S)
        self.sock.connect(("127.0.0.1", port))
        self.sock.sendall(handshake())
        self._buf = b""
        while b"\r\n\r\n" not in self._buf:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise ConnectionError("closed during the handshake")
            self._buf += chunk
        head, self._buf = self._buf.split(b"\r\n\r\n", 1)
        self.status_line = head.split(b"\r\n", 1)[0].decode("latin-1")
        self.upgraded = " 101 " in self.status_line
        self.channels: dict[str, int] = {}

    def _exact(self, n: int) -> bytes:
        while len(self._buf) < n:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise ConnectionError("the server closed the connection")
            self._buf += chunk
        out, self._buf = self._buf[:n], self._buf[n:]
        return out

    def frame(self) -> tuple[int, bytes]:
        while True:
            b0, b1 = self._exact(2)
            n = b1 & 0x7F
            if n == 126:
                n = struct.unpack(">H", self._exact(2))[0]
            elif n == 127:
                n = struct.unpack(">Q", self._exact(8))[0]
            payload = self._exact(n)
            if b0 & 0x0F in (1, 2):
                return b0 & 0x0F, payload
            if b0 & 0x0F == 8:
                raise ConnectionError("the server sent close")

    def advertised(self) -> dict[str, int]:
        """Reads up to the channel advertisement: topic → channel id."""
        while not self.channels:
            opcode, payload = self.frame()
            if opcode == 1:
                doc = json.loads(payload)
                if doc.get("op") == "advertise":
                    self.channels = {c["topic"]: int(c["id"]) for c in doc["channels"]}
        return self.channels

    def subscribe(self, topics: Sequence[str]) -> None:
        channels = self.advertised()
        subs = [{"id": i, "channelId": channels[t]} for i, t in enumerate(topics) if t in channels]
        data = json.dumps({"op": "subscribe", "subscriptions": subs}).encode()
        mask = os.urandom(4)
        head = bytes([0x81, 0x80 | 126]) + struct.pack(">H", len(data))
        if len(data) < 126:
            head = bytes([0x81, 0x80 | len(data)])
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))

    def payload(self) -> bytes:
        """The next messageData's payload."""
        while True:
            opcode, data = self.frame()
            if opcode == 2 and data[:1] == b"\x01":
                return data[13:]

    def close(self, *, reset: bool = False) -> None:
        if reset:
            with contextlib.suppress(OSError):
                self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        self.sock.close()


@dataclass
class FloodCounts:
    tried: int = 0
    clear_error: int = 0
    unchanged: int = 0
    traceback: int = 0
    silent_change: int = 0
    loss: int = 0
    by_kind: dict[str, dict[str, int]] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    peak_connections: int = 0
    peak_queue_bytes: int = 0
    probe_messages: int = 0
    server: FrontStats | None = None

    def add(self, kind: str, verdict: str, problem: str | None = None) -> None:
        self.tried += 1
        setattr(self, verdict.replace(" ", "_"), getattr(self, verdict.replace(" ", "_")) + 1)
        row = self.by_kind.setdefault(kind, dict.fromkeys(COLUMNS[1:], 0))
        row[verdict] += 1
        if problem is not None:
            self.problems.append(f"{kind}: {problem}")

    def line(self) -> str:
        return (
            f"tried {self.tried}  clear error {self.clear_error}  unchanged {self.unchanged}  "
            f"traceback {self.traceback}  silent change {self.silent_change}  loss {self.loss}"
        )


class _Tracebacks(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        if record.exc_info or record.levelno >= logging.ERROR:
            self.records.append(record)


class _Agent:
    """Draws ``events`` on the sink over and over (a fresh view each pass, as a restarted agent
    would), recording every event-channel message it wrote."""

    def __init__(self, sink: FoxgloveSink, events: Sequence[Event], pace_s: float) -> None:
        self.sink, self.events, self.pace_s = sink, events, pace_s
        self.written: list[bytes] = []
        self.failures: list[str] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="wsflood-agent", daemon=True)

    def write(self, message: lv.LiveMessage) -> None:
        self.sink.write(message)
        if message.topic == lv.EVENTS:
            self.written.append(message.data)

    def close(self) -> None:
        pass

    def first(self) -> None:
        """The first event, drawn before the probe subscribes (resent to it on subscribing)."""
        self._view = lv.LiveView(load_context(_home(self.events)), [self])
        self._view.apply(self.events[0])

    def start(self) -> None:
        self._thread.start()

    def _run(self) -> None:
        rest: Sequence[Event] = self.events[1:]
        while not self._stop.is_set():
            for event in rest:
                if self._stop.is_set():
                    return
                try:
                    self._view.apply(event)
                except Exception as exc:  # the agent must never see a viewer's trouble
                    self.failures.append(repr(exc))
                    return
                time.sleep(self.pace_s)
            self._view = lv.LiveView(self._view.ctx, [self])
            rest = self.events

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=DEADLINE_S)


def _home(events: Sequence[Event]) -> str:
    first = events[0]
    if first.type != "run_started":
        raise ValueError("the battery draws a log that starts with run_started")
    return str(first.payload["home"])


class _Probe:
    """The well-behaved viewer: subscribed to the event channel, reading on its own thread."""

    def __init__(self, port: int) -> None:
        self.viewer = Viewer(port)
        self.viewer.subscribe([lv.EVENTS])
        self.got: list[bytes] = []
        self.error: str | None = None
        self.first = self.viewer.payload()  # the latched first event
        self._thread = threading.Thread(target=self._read, name="wsflood-probe", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        try:
            while True:
                self.got.append(self.viewer.payload())
        except (OSError, ConnectionError) as exc:
            self.error = str(exc)

    def close(self) -> None:
        self.viewer.close()
        self._thread.join(timeout=DEADLINE_S)


class _Hostile:
    """One hostile connection, driven a tick at a time from the battery's thread."""

    def __init__(self, kind: str, port: int, rng: random.Random) -> None:
        self.kind = kind
        self.received = b""
        self.closed_by_server = False
        self.left = False  # it ended the connection itself
        self.viewer: Viewer | None = None
        self.sock: socket.socket
        if kind in VALID:
            rcvbuf = 4096 if kind == "nonreader" else None
            self.viewer = Viewer(port, rcvbuf=rcvbuf)
            self.sock = self.viewer.sock
            self.received = self.viewer.status_line.encode()
            if self.viewer.upgraded and kind == "nonreader":
                self.viewer.subscribe(list(lv.CHANNELS))
            elif self.viewer.upgraded and kind == "reset":
                self.viewer.subscribe([lv.EVENTS])
                self.viewer.payload()
                self.viewer.close(reset=True)
                self.left = True
            elif not self.viewer.upgraded:
                self.closed_by_server = True
            return
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=DEADLINE_S)
        self.pending = handshake() if kind == "drip" else b""
        opening = {
            "junk": bytes(rng.randrange(256) for _ in range(rng.randrange(1, 400))) + b"\r\n\r\n",
            "oversize": b"GET / HTTP/1.1\r\nX-Pad: " + b"a" * (70 * 1024),
            "plain": b"GET /index.html HTTP/1.1\r\nHost: x\r\n\r\n",
            "subprotocol": handshake("foxglove.websocket.v2"),
            "hangup": handshake()[: rng.randrange(1, 40)],
        }.get(kind, b"")
        with contextlib.suppress(OSError):  # the server may answer and close before the end
            self.sock.sendall(opening)
        self.sock.setblocking(False)
        if kind == "hangup":
            self.sock.close()
            self.left = True

    def tick(self) -> None:
        if self.left or self.closed_by_server or self.kind in VALID:
            return
        if self.kind == "drip" and self.pending[1:]:  # never the last byte: never finished
            with contextlib.suppress(OSError):
                self.sock.send(self.pending[:1])
            self.pending = self.pending[1:]
        try:
            data = self.sock.recv(65536)
        except BlockingIOError:
            return
        except OSError:
            self.closed_by_server = True
            return
        if data:
            self.received += data
        else:
            self.closed_by_server = True

    def settled(self) -> bool:
        return self.left or self.closed_by_server or self.kind in VALID

    def verdict(self) -> tuple[str, str | None]:
        status = self.received.split(b"\r\n", 1)[0].decode("latin-1", "replace")
        if self.kind in ("hangup", "reset"):
            return "unchanged", None
        if self.kind in VALID:
            if " 101 " in status:
                return "unchanged", None
            if " 503 " in status:
                return "clear error", None
            return "silent change", f"answered {status!r}"
        if " 101 " in status:
            return "silent change", "a bad handshake was upgraded"
        if not self.closed_by_server:
            return "silent change", "still open after every deadline"
        if self.kind in ("drip", "silent"):  # closed unanswered, or refused at the cap
            if not status or " 503 " in status:
                return "clear error", None
            return "silent change", f"got {status!r}"
        if " 400 " in status or " 503 " in status or not status:
            return "clear error", None
        return "silent change", f"answered {status!r}"

    def close(self) -> None:
        if self.viewer is not None:
            self.viewer.close()
        else:
            self.sock.close()


def run_battery(
    events: Sequence[Event],
    cases: int,
    seed: int,
    *,
    limits: FrontLimits | None = None,
    per_round: int = 24,
    pace_s: float = 0.002,
) -> FloodCounts:
    """``cases`` hostile connections in rounds of ``per_round`` against a live view drawing
    ``events`` (a log starting with ``run_started``) over and over; see the module's doc."""
    limits = limits or FrontLimits(
        max_clients=8, client_queue_bytes=64 * 1024, handshake_timeout_s=2.0
    )
    rng = random.Random(seed)
    counts = FloodCounts()
    tracebacks = _Tracebacks()
    logger = logging.getLogger("objsearch.liveview")
    logger.addHandler(tracebacks)
    sink = FoxgloveSink(port=0, limits=limits)
    agent = _Agent(sink, events, pace_s)
    probe: _Probe | None = None
    try:
        agent.first()
        probe = _Probe(sink.port)
        agent.start()
        done = 0
        while done < cases:
            n = min(per_round, cases - done)
            _round(sink, limits, [rng.choice(KINDS) for _ in range(n)], rng, counts)
            done += n
            try:  # a fresh viewer gets in after every round
                fresh = Viewer(sink.port)
                if not fresh.upgraded:
                    counts.loss += 1
                    counts.problems.append(f"a fresh viewer was refused: {fresh.status_line}")
                fresh.close()
            except (OSError, ConnectionError) as exc:
                counts.loss += 1
                counts.problems.append(f"a fresh viewer could not connect: {exc}")
        agent.stop()
        deadline = time.monotonic() + DEADLINE_S
        while _matched(probe, agent.written)[0] < len(agent.written) and probe.error is None:
            if time.monotonic() > deadline:
                break
            time.sleep(0.05)
        counts.probe_messages = len(probe.got)
        _check_probe(probe, agent.written, counts)
        if agent.failures:
            counts.traceback += len(agent.failures)
            counts.problems.extend(f"the agent: {f}" for f in agent.failures)
    finally:
        agent.stop()
        if probe is not None:
            probe.close()
        stats = sink.stats()
        sink.close()
        logger.removeHandler(tracebacks)
    counts.peak_queue_bytes = stats.peak_queue_bytes
    counts.server = stats
    if stats.peak_queue_bytes > limits.client_queue_bytes + 64 * 1024:
        counts.silent_change += 1
        counts.problems.append(f"a queue held {stats.peak_queue_bytes} bytes")
    own = [r for r in tracebacks.records if r.name.startswith("objsearch")]
    counts.traceback += len(own)
    counts.problems.extend(f"logged: {r.getMessage()}" for r in own)
    return counts


def _check_probe(probe: _Probe, written: list[bytes], counts: FloodCounts) -> None:
    """Every message written after the probe subscribed reached it, in order. A channel's last
    message is sent again to every subscriber whenever anyone subscribes (the SDK's ``log`` has
    no single recipient): such a repeat is allowed, anything else is a change."""
    if probe.first != written[0]:
        counts.loss += 1
        counts.problems.append("the probe did not get the latched first message")
    at, strays = _matched(probe, written)
    if strays:
        counts.silent_change += strays
        counts.problems.append(f"the probe got {strays} messages out of order")
    if at < len(written):
        counts.loss += len(written) - at
        counts.problems.append(
            f"the probe got {at - 1} of {len(written) - 1} messages ({probe.error or 'no error'})"
        )


def _matched(probe: _Probe, written: list[bytes]) -> tuple[int, int]:
    """(how many of ``written`` the probe got in order, counting the latched first; how many
    messages it got that are neither the next one nor a repeat of the last)."""
    at, strays = 1, 0
    for got in list(probe.got):  # a copy: the probe's thread appends
        if at < len(written) and got == written[at]:
            at += 1
        elif got != written[at - 1]:
            strays += 1
    return at, strays


def _round(
    sink: FoxgloveSink,
    limits: FrontLimits,
    kinds: list[str],
    rng: random.Random,
    counts: FloodCounts,
) -> None:
    before = sink.stats()
    hostile: list[_Hostile] = []
    try:
        for kind in kinds:
            hostile.append(_Hostile(kind, sink.port, rng))
        deadline = time.monotonic() + limits.handshake_timeout_s + DEADLINE_S
        while not all(h.settled() for h in hostile) and time.monotonic() < deadline:
            for h in hostile:
                h.tick()
            held = sink.stats().connections
            counts.peak_connections = max(counts.peak_connections, held)
            if held > limits.max_clients:
                counts.silent_change += 1
                counts.problems.append(f"{held} connections held, over the cap")
            time.sleep(0.05)
        for h in hostile:
            verdict, problem = h.verdict()
            counts.add(h.kind, verdict, problem)
    finally:
        for h in hostile:
            h.close()
    # Every place taken this round is freed again: only the probe stays.
    deadline = time.monotonic() + DEADLINE_S
    while sink.stats().connections > before.connections and time.monotonic() < deadline:
        time.sleep(0.05)
    leaked = sink.stats().connections - before.connections
    if leaked > 0:
        counts.silent_change += leaked
        counts.problems.append(f"{leaked} places not freed after a round")


def report(counts: FloodCounts) -> list[str]:
    """The counts as the batteries print them: the totals, then one row per kind."""
    lines = [counts.line()]
    header = "  ".join(f"{c:>13}" for c in COLUMNS[1:])
    lines.append(f"  {'kind':12} {'tried':>6}  {header}")
    for kind in KINDS:
        row = counts.by_kind.get(kind)
        if row:
            cells = "  ".join(f"{row[c]:>13}" for c in COLUMNS[1:])
            lines.append(f"  {kind:12} {sum(row.values()):>6}  {cells}")
    return lines
