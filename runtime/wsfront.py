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
"""

from __future__ import annotations

import contextlib
import logging
import socket
import threading
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
_HANDSHAKE_TIMEOUT_S = 10.0


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


def _read_head(sock: socket.socket) -> tuple[bytes, bytes]:
    """(head without its blank line, bytes read past it)."""
    buf = b""
    while b"\r\n\r\n" not in buf:
        if len(buf) > _MAX_HEAD:
            raise HandshakeRefused(f"handshake longer than {_MAX_HEAD} bytes")
        chunk = sock.recv(65536)
        if not chunk:
            raise ConnectionError("closed during the handshake")
        buf += chunk
    head, rest = buf.split(b"\r\n\r\n", 1)
    return head, rest


def _refusal(reason: str) -> bytes:
    body = (reason + "\n").encode("utf-8")
    return (
        b"HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain; charset=utf-8\r\n"
        + f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n".encode()
        + body
    )


class SubprotocolFront:
    """Listens on ``host:port`` and relays each Foxglove client to ``backend_port`` on loopback.

    Raises :class:`OSError` if ``host:port`` cannot be bound; ``port`` 0 picks a free one
    (:attr:`port` says which).
    """

    def __init__(self, host: str, port: int, backend_port: int) -> None:
        family = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0][0]
        self._listener = socket.create_server((host, port), family=family)
        self.host = host
        self.port = int(self._listener.getsockname()[1])
        self.backend_port = backend_port
        self._open: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._closed = False
        self._thread = threading.Thread(target=self._accept, name="liveview-front", daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        while True:
            try:
                conn, peer = self._listener.accept()
            except OSError:
                return  # closed
            threading.Thread(
                target=self._serve, args=(conn, peer), name="liveview-client", daemon=True
            ).start()

    def _track(self, *socks: socket.socket) -> bool:
        with self._lock:
            if self._closed:
                return False
            self._open.update(socks)
            return True

    def _serve(self, client: socket.socket, peer: tuple[str, int]) -> None:
        who = f"{peer[0]}:{peer[1]}"
        backend: socket.socket | None = None
        try:
            if not self._track(client):
                return
            client.settimeout(_HANDSHAKE_TIMEOUT_S)
            try:
                head, rest = _read_head(client)
                request = Handshake.parse(head)
                chosen = choose_subprotocol(request)
            except HandshakeRefused as refused:
                log.warning("live view: refused the WebSocket handshake of %s: %s", who, refused)
                with contextlib.suppress(OSError):
                    client.sendall(_refusal(refused.reason))
                return
            except (OSError, ConnectionError, UnicodeError) as exc:
                log.warning("live view: WebSocket handshake of %s failed: %s", who, exc)
                return
            backend = socket.create_connection(
                ("127.0.0.1", self.backend_port), timeout=_HANDSHAKE_TIMEOUT_S
            )
            if not self._track(backend):
                return
            backend.sendall(request.with_header("Sec-WebSocket-Protocol", SDK_SUBPROTOCOL).encode())
            backend.sendall(rest)
            answer_head, answer_rest = _read_head(backend)
            answer = Handshake.parse(answer_head)
            if answer.status != 101:
                log.warning(
                    "live view: the Foxglove server refused the WebSocket handshake of %s "
                    "(offered %s): %s %s",
                    who,
                    ", ".join(request.values("Sec-WebSocket-Protocol")),
                    answer.first_line,
                    answer_rest[:200].decode("utf-8", "replace").strip(),
                )
                client.sendall(answer_head + b"\r\n\r\n" + answer_rest)
                return
            client.sendall(answer.with_header("Sec-WebSocket-Protocol", chosen).encode())
            client.sendall(answer_rest)
            log.info("live view: Foxglove client %s connected (%s)", who, chosen)
            for s in (client, backend):
                s.settimeout(None)
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            back = threading.Thread(
                target=_pump, args=(backend, client), name="liveview-relay", daemon=True
            )
            back.start()
            _pump(client, backend)
            back.join()
        except (OSError, ConnectionError, HandshakeRefused) as exc:
            log.warning("live view: connection of %s ended: %s", who, exc)
        finally:
            ends: list[socket.socket | None] = [client, backend]
            for end in ends:
                if end is not None:
                    with self._lock:
                        self._open.discard(end)
                    end.close()

    def close(self) -> None:
        """Stop listening and drop every client."""
        with self._lock:
            self._closed = True
            socks = list(self._open)
        with contextlib.suppress(OSError):
            self._listener.shutdown(socket.SHUT_RDWR)
        self._listener.close()
        for s in socks:
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)
        self._thread.join(timeout=5)


def _pump(src: socket.socket, dst: socket.socket) -> None:
    """Copy ``src`` to ``dst`` until ``src`` ends, then end ``dst``'s sending side."""
    try:
        while chunk := src.recv(65536):
            dst.sendall(chunk)
    except OSError:
        pass
    finally:
        with contextlib.suppress(OSError):
            dst.shutdown(socket.SHUT_WR)
