"""The live view's WebSocket front door: both names of the Foxglove WebSocket protocol.

foxglove-sdk's server (every release up to 0.30 at least: ``rust/foxglove/src/websocket/
handshake.rs``) accepts one subprotocol, ``foxglove.sdk.v1``, and has no option for another; any
other offer gets HTTP 400 "Missing expected sec-websocket-protocol header" before the SDK's
listener hears of the client, and the SDK logs only "handshake failed". Foxglove's published
client, ``@foxglove/ws-protocol`` (0.8.0, ``FoxgloveClient.SUPPORTED_SUBPROTOCOL``), and the
Foxglove and Lichtblick apps before the rename offer ``foxglove.websocket.v1``: the same protocol
under its earlier name (Foxglove's stated position; ``foxglove_bridge`` 3.x made the same switch).

So the SDK listens on a loopback port of its own and :class:`SubprotocolFront` listens where the
user asked. It reads each client's opening handshake, chooses ``foxglove.sdk.v1`` if offered,
else ``foxglove.websocket.v1``, hands the handshake to the SDK under the name the SDK knows, and
answers the client under the name it offered; after that it copies bytes both ways untouched.
A handshake it refuses, or the SDK refuses, is logged with its reason (who, what was offered,
what the server said).

A viewer must never cost the agent its memory or the other viewers their stream, so one thread
serves every connection and :class:`FrontLimits` bounds them: how many at once, how long a
handshake may take, how many bytes may wait for one client before it is dropped.
"""

from __future__ import annotations

import contextlib
import enum
import errno
import logging
import os
import selectors
import socket
import struct
import threading
import time
from dataclasses import dataclass
from typing import Final

log = logging.getLogger("objsearch.liveview")

#: The name foxglove-sdk's server accepts.
SDK_SUBPROTOCOL: Final = "foxglove.sdk.v1"
#: The earlier name of the same protocol, which ``@foxglove/ws-protocol`` offers.
LEGACY_SUBPROTOCOL: Final = "foxglove.websocket.v1"
#: In order of preference.
SUBPROTOCOLS: Final = (SDK_SUBPROTOCOL, LEGACY_SUBPROTOCOL)

_MAX_HEAD = 64 * 1024
_CHUNK = 64 * 1024

#: How many clients the live view serves at once unless told otherwise (``--live-max-clients``).
DEFAULT_MAX_CLIENTS: Final = 32
#: Bytes waiting for one client before it is dropped as too slow (``--live-client-queue``).
DEFAULT_CLIENT_QUEUE_BYTES: Final = 4 * 1024 * 1024
#: Seconds from accepting a connection to the end of its WebSocket handshake.
DEFAULT_HANDSHAKE_TIMEOUT_S: Final = 10.0
#: Upper bounds of the options (a front door is not a load balancer).
MAX_CLIENTS_LIMIT: Final = 1024
MAX_QUEUE_BYTES_LIMIT: Final = 1024 * 1024 * 1024
#: Seconds between two log lines about the same kind of refusal (a flood is summarised).
_LOG_EVERY_S = 10.0


class HandshakeRefused(Exception):
    """A request the front door answers itself with HTTP 400 (``reason`` says why)."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True, slots=True)
class Handshake:
    """An HTTP request or response head: the first line and the header lines as sent."""

    first_line: str
    headers: tuple[tuple[str, str], ...]

    @classmethod
    def parse(cls, head: bytes) -> Handshake:
        lines = head.decode("latin-1").split("\r\n")
        headers = []
        for line in lines[1:]:
            name, sep, value = line.partition(":")
            if not sep:
                raise HandshakeRefused(f"malformed header line {line[:80]!r}")
            headers.append((name.strip(), value.strip()))
        return cls(lines[0], tuple(headers))

    def values(self, name: str) -> list[str]:
        """Every comma-separated value of every header called ``name`` (case-insensitive)."""
        out: list[str] = []
        for key, value in self.headers:
            if key.lower() == name.lower():
                out.extend(v.strip() for v in value.split(",") if v.strip())
        return out

    def with_header(self, name: str, value: str) -> Handshake:
        """This head with every ``name`` header replaced by one ``name: value``."""
        kept = tuple((k, v) for k, v in self.headers if k.lower() != name.lower())
        return Handshake(self.first_line, (*kept, (name, value)))

    def encode(self) -> bytes:
        lines = [self.first_line, *(f"{k}: {v}" for k, v in self.headers)]
        return ("\r\n".join(lines) + "\r\n\r\n").encode("latin-1")

    @property
    def status(self) -> int:
        """The status code of a response head (0 if there is none)."""
        parts = self.first_line.split(" ", 2)
        return int(parts[1]) if len(parts) > 1 and parts[1].isdigit() else 0


def choose_subprotocol(request: Handshake) -> str:
    """The subprotocol to answer ``request`` with, or :class:`HandshakeRefused` saying why."""
    if "websocket" not in (v.lower() for v in request.values("Upgrade")):
        raise HandshakeRefused(
            f"not a WebSocket upgrade ({request.first_line[:80]!r}); this port serves the "
            "Foxglove WebSocket protocol: open it in Foxglove as ws://HOST:PORT"
        )
    offered = request.values("Sec-WebSocket-Protocol")
    for name in SUBPROTOCOLS:
        if name in offered:
            return name
    what = ", ".join(offered) if offered else "no subprotocol"
    raise HandshakeRefused(
        f"Missing expected sec-websocket-protocol header: the client offered {what}; "
        f"this server speaks {' or '.join(SUBPROTOCOLS)}"
    )


@dataclass(frozen=True, slots=True)
class FrontLimits:
    """What one client may cost: a place among ``max_clients``, ``client_queue_bytes`` of
    messages waiting for it, ``handshake_timeout_s`` to finish its handshake."""

    max_clients: int = DEFAULT_MAX_CLIENTS
    client_queue_bytes: int = DEFAULT_CLIENT_QUEUE_BYTES
    handshake_timeout_s: float = DEFAULT_HANDSHAKE_TIMEOUT_S

    def __post_init__(self) -> None:
        if not isinstance(self.max_clients, int) or not 1 <= self.max_clients <= MAX_CLIENTS_LIMIT:
            raise ValueError(
                f"the live view's client limit must be a whole number 1–{MAX_CLIENTS_LIMIT}, "
                f"not {self.max_clients!r}"
            )
        if (
            not isinstance(self.client_queue_bytes, int)
            or not _CHUNK <= self.client_queue_bytes <= MAX_QUEUE_BYTES_LIMIT
        ):
            raise ValueError(
                f"the live view's per-client queue must be {_CHUNK} bytes to 1 GiB, "
                f"not {self.client_queue_bytes!r}"
            )
        timeout = self.handshake_timeout_s
        if not isinstance(timeout, int | float) or not 0 < timeout <= 3600:  # NaN fails too
            raise ValueError(
                f"the live view's handshake timeout must be above 0 and at most 3600 s, "
                f"not {timeout!r}"
            )


@dataclass(frozen=True, slots=True)
class FrontStats:
    """What the front door has done so far, and what it holds now (:meth:`SubprotocolFront.stats`)."""

    #: Connections held now (handshaking and relaying); never more than ``max_clients``.
    connections: int
    #: Of those, the ones still in their handshake.
    handshaking: int
    #: Connections accepted in all (including those then refused, evicted or dropped).
    accepted: int
    #: Answered HTTP 503 because ``max_clients`` clients were connected.
    refused_full: int
    #: Closed in their handshake to make room for a newer connection while at the cap.
    evicted: int
    #: Closed because their handshake took longer than ``handshake_timeout_s``.
    timed_out: int
    #: Dropped because more than ``client_queue_bytes`` were waiting for them.
    dropped_slow: int
    #: The most bytes that ever waited for one client.
    peak_queue_bytes: int


def _response(status: str, reason: str, *extra: str) -> bytes:
    """A complete HTTP response that ends the connection (a refusal before any upgrade)."""
    body = (reason + "\n").encode("utf-8")
    head = [
        f"HTTP/1.1 {status}",
        "Content-Type: text/plain; charset=utf-8",
        f"Content-Length: {len(body)}",
        *extra,
        "Connection: close",
    ]
    return ("\r\n".join(head) + "\r\n\r\n").encode("latin-1") + body


def _refusal(reason: str) -> bytes:
    return _response("400 Bad Request", reason)


class _Phase(enum.Enum):
    HEAD = "reading the client's handshake"
    BACKEND = "waiting for the Foxglove server's answer"
    RELAY = "relaying"
    CLOSING = "sending a refusal"


#: Seconds a refused connection is given to read its answer before it is closed.
_LINGER_S = 2.0


class _Conn:
    """One client: its socket, the SDK-side socket once there is one, and what waits for each."""

    def __init__(self, client: socket.socket, who: str, deadline: float, holds_slot: bool) -> None:
        self.client = client
        self.who = who
        self.deadline: float | None = deadline
        self.holds_slot = holds_slot
        self.phase = _Phase.HEAD
        self.backend: socket.socket | None = None
        self.connecting = False
        self.head = bytearray()
        self.chosen = ""
        self.offered = ""
        self.to_client = bytearray()
        self.to_backend = bytearray()
        self.client_eof = False
        self.backend_eof = False
        self.write_shut = False  # CLOSING: the answer is out, the client's side is ended
        self.masks: dict[int, int] = {}


class _Throttle:
    """Warnings of one kind at most once per ``_LOG_EVERY_S``; the rest are counted and summed up
    in one line, so a flood of connections cannot flood the log."""

    def __init__(self) -> None:
        self._last: dict[str, float] = {}
        self._quiet: dict[str, int] = {}

    def warn(self, kind: str, message: str) -> None:
        now = time.monotonic()
        last = self._last.get(kind)
        if last is not None and now - last < _LOG_EVERY_S:
            self._quiet[kind] = self._quiet.get(kind, 0) + 1
            return
        self._last[kind] = now
        log.warning("live view: %s", message)

    def flush(self) -> None:
        now = time.monotonic()
        for kind, quiet in list(self._quiet.items()):
            if now - self._last[kind] >= _LOG_EVERY_S:
                del self._quiet[kind]
                self._last[kind] = now
                log.warning(
                    "live view: %d more connections %s in the last %.0f s",
                    quiet,
                    kind,
                    _LOG_EVERY_S,
                )


class SubprotocolFront:
    """Listens on ``host:port`` and relays each Foxglove client to ``backend_port`` on loopback.

    One thread serves every connection (a selector loop), so connections cost sockets and
    buffers, never threads, and ``limits`` bounds both: at most ``max_clients`` connections; a
    handshake unfinished after ``handshake_timeout_s`` is closed; a client with more than
    ``client_queue_bytes`` waiting for it is dropped. A connection over the cap closes the oldest
    one still in its handshake, or, when every place holds a connected client, is answered
    HTTP 503.

    Raises :class:`OSError` if ``host:port`` cannot be bound; ``port`` 0 picks a free one
    (:attr:`port` says which).
    """

    def __init__(
        self, host: str, port: int, backend_port: int, limits: FrontLimits | None = None
    ) -> None:
        self.limits = limits or FrontLimits()
        family = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0][0]
        self._listener = socket.create_server((host, port), family=family)
        self._listener.setblocking(False)
        self.host = host
        self.port = int(self._listener.getsockname()[1])
        self.backend_port = backend_port
        self._selector = selectors.DefaultSelector()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._selector.register(self._listener, selectors.EVENT_READ, None)
        self._selector.register(self._wake_r, selectors.EVENT_READ, None)
        # Insertion order is acceptance order: the first unfinished handshake is the oldest.
        self._conns: dict[int, _Conn] = {}
        self._refusing: dict[int, _Conn] = {}
        self._throttle = _Throttle()
        self._closed = False
        self._counts = dict.fromkeys(
            ("accepted", "refused_full", "evicted", "timed_out", "dropped_slow", "peak"), 0
        )
        self._stats = self._snapshot()
        self._thread = threading.Thread(target=self._loop, name="liveview-front", daemon=True)
        self._thread.start()

    # -- what it holds ---------------------------------------------------------------------------

    def stats(self) -> FrontStats:
        """The counts as of the loop's last turn (it turns at least once a second)."""
        return self._stats

    def _snapshot(self) -> FrontStats:
        held = [c for c in self._conns.values() if c.holds_slot]
        c = self._counts
        return FrontStats(
            connections=len(held),
            handshaking=sum(x.phase is not _Phase.RELAY for x in held),
            accepted=c["accepted"],
            refused_full=c["refused_full"],
            evicted=c["evicted"],
            timed_out=c["timed_out"],
            dropped_slow=c["dropped_slow"],
            peak_queue_bytes=c["peak"],
        )

    # -- the loop --------------------------------------------------------------------------------

    def _loop(self) -> None:
        try:
            while not self._closed:
                timeout = self._next_timeout()
                for key, mask in self._selector.select(timeout):
                    if key.fileobj is self._listener:
                        self._accept()
                    elif key.fileobj is self._wake_r:
                        with contextlib.suppress(OSError):
                            self._wake_r.recv(4096)
                    else:
                        conn, side = key.data
                        self._serve(conn, side, mask)
                self._expire()
                self._throttle.flush()
                self._stats = self._snapshot()
        except Exception:  # boundary: a bug here must not take the agent down (logged)
            log.exception("live view: the WebSocket front door stopped")
        finally:
            for conn in [*self._conns.values(), *self._refusing.values()]:
                self._close(conn, reset=True)
            if not self._closed:  # stopped by a bug: refuse connections rather than queue them
                self._listener.close()
            self._stats = self._snapshot()

    def _next_timeout(self) -> float:
        deadlines = [
            c.deadline
            for c in [*self._conns.values(), *self._refusing.values()]
            if c.deadline is not None
        ]
        if not deadlines:
            return 1.0
        return min(max(min(deadlines) - time.monotonic(), 0.0), 1.0)

    def _accept(self) -> None:
        for _ in range(64):  # then let the clients' sockets have a turn
            try:
                sock, peer = self._listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:  # out of file descriptors, …: the connection waits
                self._throttle.warn("not accepted", f"cannot accept a connection: {exc}")
                return
            sock.setblocking(False)
            who = f"{peer[0]}:{peer[1]}"
            self._counts["accepted"] += 1
            deadline = time.monotonic() + self.limits.handshake_timeout_s
            held = sum(c.holds_slot for c in self._conns.values())
            if held >= self.limits.max_clients:
                oldest = next(
                    (
                        c
                        for c in self._conns.values()
                        if c.holds_slot and c.phase is not _Phase.RELAY
                    ),
                    None,
                )
                if oldest is None:
                    self._refuse_full(sock, who)
                    continue
                self._counts["evicted"] += 1
                self._throttle.warn(
                    "closed unfinished to make room",
                    f"closed the unfinished handshake of {oldest.who} ({oldest.phase.value}) to "
                    f"make room for {who}: {self.limits.max_clients} connections is the limit",
                )
                self._close(oldest, reset=True)
            conn = _Conn(sock, who, deadline, holds_slot=True)
            self._conns[sock.fileno()] = conn
            self._update(conn)

    def _refuse_full(self, sock: socket.socket, who: str) -> None:
        self._counts["refused_full"] += 1
        self._throttle.warn(
            "refused at the limit",
            f"refused {who}: {self.limits.max_clients} Foxglove clients are connected, the "
            "limit (--live-max-clients)",
        )
        conn = _Conn(sock, who, time.monotonic() + _LINGER_S, holds_slot=False)
        conn.phase = _Phase.CLOSING
        conn.to_client += _response(
            "503 Service Unavailable",
            f"the live view serves at most {self.limits.max_clients} clients at once and has "
            "that many; try again later",
            "Retry-After: 5",
        )
        # Refusals wait for their answer to be read, but there are never more of them than places.
        if len(self._refusing) >= self.limits.max_clients:
            self._close(next(iter(self._refusing.values())), reset=True)
        self._refusing[sock.fileno()] = conn
        self._update(conn)

    def _expire(self) -> None:
        now = time.monotonic()
        for conn in [*self._conns.values(), *self._refusing.values()]:
            if conn.deadline is None or conn.deadline > now:
                continue
            if conn.phase is _Phase.CLOSING:
                self._close(conn, reset=True)
                continue
            self._counts["timed_out"] += 1
            self._throttle.warn(
                "closed for a slow handshake",
                f"closed {conn.who}: its WebSocket handshake was not done after "
                f"{self.limits.handshake_timeout_s:g} s ({conn.phase.value})",
            )
            self._close(conn, reset=True)

    # -- one connection ---------------------------------------------------------------------------

    def _serve(self, conn: _Conn, side: str, mask: int) -> None:
        if not self._open(conn):  # closed earlier in this turn (evicted, dropped)
            return
        try:
            if side == "client":
                if mask & selectors.EVENT_WRITE:
                    self._write_client(conn)
                if mask & selectors.EVENT_READ and self._open(conn):
                    self._read_client(conn)
            else:
                if mask & selectors.EVENT_WRITE:
                    self._write_backend(conn)
                if mask & selectors.EVENT_READ and self._open(conn):
                    self._read_backend(conn)
        except (BlockingIOError, InterruptedError):
            pass
        except OSError as exc:
            self._end(conn, f"connection of {conn.who} ended: {exc}")
            return
        except Exception:  # boundary: a bug met by one connection ends it, not the front door
            log.exception("live view: dropped %s after an unexpected error", conn.who)
            self._close(conn, reset=True)
            return
        if self._open(conn):
            self._update(conn)

    def _open(self, conn: _Conn) -> bool:
        key = conn.client.fileno()
        return key != -1 and (self._conns.get(key) is conn or self._refusing.get(key) is conn)

    def _read_client(self, conn: _Conn) -> None:
        data = conn.client.recv(_CHUNK)
        if conn.phase is _Phase.CLOSING:
            if not data:  # it read the answer and hung up
                self._close(conn)
            return  # what it sends after a refusal is read and dropped
        if not data:
            if conn.phase is _Phase.RELAY:
                conn.client_eof = True
                self._maybe_finish(conn)
            else:
                self._end(
                    conn, f"WebSocket handshake of {conn.who} failed: closed during the handshake"
                )
            return
        if conn.phase is _Phase.RELAY:
            conn.to_backend += data
            return
        conn.head += data
        if b"\r\n\r\n" not in conn.head:
            if len(conn.head) > _MAX_HEAD:
                self._refuse(conn, f"handshake longer than {_MAX_HEAD} bytes")
            return
        head, rest = bytes(conn.head).split(b"\r\n\r\n", 1)
        conn.head.clear()
        try:
            request = Handshake.parse(head)
            conn.chosen = choose_subprotocol(request)
        except HandshakeRefused as refused:
            self._refuse(conn, refused.reason)
            return
        conn.offered = ", ".join(request.values("Sec-WebSocket-Protocol"))
        conn.to_backend += request.with_header("Sec-WebSocket-Protocol", SDK_SUBPROTOCOL).encode()
        conn.to_backend += rest
        backend = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        backend.setblocking(False)
        conn.backend = backend
        conn.phase = _Phase.BACKEND
        conn.connecting = True
        err = backend.connect_ex(("127.0.0.1", self.backend_port))
        if err not in (0, errno.EINPROGRESS, errno.EWOULDBLOCK):
            raise OSError(err, f"cannot reach the Foxglove server: {os.strerror(err)}")

    def _refuse(self, conn: _Conn, reason: str) -> None:
        self._throttle.warn(
            "refused for a bad handshake",
            f"refused the WebSocket handshake of {conn.who}: {reason}",
        )
        conn.phase = _Phase.CLOSING
        conn.deadline = time.monotonic() + _LINGER_S
        conn.to_client += _refusal(reason)

    def _write_client(self, conn: _Conn) -> None:
        sent = conn.client.send(conn.to_client)
        del conn.to_client[:sent]
        if conn.to_client:
            return
        if conn.phase is _Phase.CLOSING and not conn.write_shut:
            # Ended, then read until the client hangs up: closing with its request unread would
            # reset the connection and could lose the answer before the client reads it.
            conn.write_shut = True
            conn.client.shutdown(socket.SHUT_WR)
        elif conn.phase is _Phase.RELAY:
            self._maybe_finish(conn)

    def _write_backend(self, conn: _Conn) -> None:
        assert conn.backend is not None
        if conn.connecting:
            err = conn.backend.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR)
            if err:
                raise OSError(err, f"cannot reach the Foxglove server: {os.strerror(err)}")
            conn.connecting = False
        if conn.to_backend:
            sent = conn.backend.send(conn.to_backend)
            del conn.to_backend[:sent]
        if not conn.to_backend and conn.phase is _Phase.RELAY:
            self._maybe_finish(conn)

    def _read_backend(self, conn: _Conn) -> None:
        assert conn.backend is not None
        data = conn.backend.recv(_CHUNK)
        if not data:
            if conn.phase is _Phase.RELAY:
                conn.backend_eof = True
                self._maybe_finish(conn)
            else:
                self._end(conn, f"the Foxglove server hung up on {conn.who} during the handshake")
            return
        if conn.phase is _Phase.RELAY:
            conn.to_client += data
            self._counts["peak"] = max(self._counts["peak"], len(conn.to_client))
            if len(conn.to_client) > self.limits.client_queue_bytes:
                self._counts["dropped_slow"] += 1
                self._throttle.warn(
                    "dropped for not reading",
                    f"dropped {conn.who}: {len(conn.to_client)} bytes were waiting for it, over "
                    f"the limit of {self.limits.client_queue_bytes} (--live-client-queue); "
                    "a client that does not keep up is dropped",
                )
                self._close(conn, reset=True)
            return
        conn.head += data
        if b"\r\n\r\n" not in conn.head:
            if len(conn.head) > _MAX_HEAD:
                self._end(conn, f"the Foxglove server's answer to {conn.who} is too long")
            return
        head, rest = bytes(conn.head).split(b"\r\n\r\n", 1)
        conn.head.clear()
        answer = Handshake.parse(head)
        if answer.status != 101:
            self._throttle.warn(
                "refused by the Foxglove server",
                f"the Foxglove server refused the WebSocket handshake of {conn.who} (offered "
                f"{conn.offered}): {answer.first_line} "
                f"{rest[:200].decode('utf-8', 'replace').strip()}",
            )
            conn.phase = _Phase.CLOSING
            conn.deadline = time.monotonic() + _LINGER_S
            conn.to_client += head + b"\r\n\r\n" + rest
            self._register(conn, conn.backend, 0, "backend")
            conn.backend.close()
            conn.backend = None
            return
        conn.to_client += answer.with_header("Sec-WebSocket-Protocol", conn.chosen).encode()
        conn.to_client += rest
        conn.phase = _Phase.RELAY
        conn.deadline = None
        for s in (conn.client, conn.backend):
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        log.info("live view: Foxglove client %s connected (%s)", conn.who, conn.chosen)

    def _maybe_finish(self, conn: _Conn) -> None:
        """Pass each side's end on once what it sent is through; close when both have ended."""
        assert conn.backend is not None
        if conn.client_eof and not conn.to_backend:
            with contextlib.suppress(OSError):
                conn.backend.shutdown(socket.SHUT_WR)
        if conn.backend_eof and not conn.to_client:
            with contextlib.suppress(OSError):
                conn.client.shutdown(socket.SHUT_WR)
        if conn.client_eof and conn.backend_eof and not conn.to_client and not conn.to_backend:
            log.info("live view: Foxglove client %s disconnected", conn.who)
            self._close(conn)

    def _end(self, conn: _Conn, message: str) -> None:
        self._throttle.warn("ended with an error", message)
        self._close(conn, reset=True)

    def _update(self, conn: _Conn) -> None:
        """Register each socket for what it waits on now."""
        read, write = selectors.EVENT_READ, selectors.EVENT_WRITE
        room = len(conn.to_backend) < self.limits.client_queue_bytes
        client = 0
        if conn.phase is _Phase.HEAD or conn.phase is _Phase.CLOSING:
            client |= read
        elif conn.phase is _Phase.RELAY and not conn.client_eof and room:
            client |= read  # a client that sends faster than the server reads waits
        if conn.to_client and not conn.write_shut:
            client |= write
        self._register(conn, conn.client, client, "client")
        if conn.backend is not None:
            backend = 0
            if not conn.connecting and not conn.backend_eof:
                backend |= read
            if conn.connecting or conn.to_backend:
                backend |= write
            self._register(conn, conn.backend, backend, "backend")

    def _register(self, conn: _Conn, sock: socket.socket, mask: int, side: str) -> None:
        fd = sock.fileno()
        had = conn.masks.get(fd, 0)
        if mask == had:
            return
        if not mask:
            self._selector.unregister(sock)
            del conn.masks[fd]
        elif not had:
            self._selector.register(sock, mask, (conn, side))
            conn.masks[fd] = mask
        else:
            self._selector.modify(sock, mask, (conn, side))
            conn.masks[fd] = mask

    def _close(self, conn: _Conn, *, reset: bool = False) -> None:
        """Forget ``conn`` and close its sockets; ``reset`` discards what is unsent (RST), so a
        dropped client's backlog is freed at once rather than lingering in the kernel."""
        fd = conn.client.fileno()
        if self._conns.get(fd) is conn:
            del self._conns[fd]
        if self._refusing.get(fd) is conn:
            del self._refusing[fd]
        for sock in (conn.client, conn.backend):
            if sock is None or sock.fileno() == -1:
                continue
            if sock.fileno() in conn.masks:
                with contextlib.suppress(KeyError, ValueError):
                    self._selector.unregister(sock)
            if reset:
                with contextlib.suppress(OSError):
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            sock.close()
        conn.masks.clear()
        conn.to_client.clear()
        conn.to_backend.clear()

    def close(self) -> None:
        """Stop listening and drop every client."""
        self._closed = True
        with contextlib.suppress(OSError):
            self._wake_w.send(b"x")
        self._thread.join(timeout=10)
        self._selector.close()
        for sock in (self._listener, self._wake_r, self._wake_w):
            sock.close()
