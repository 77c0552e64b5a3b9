"""A minimal Foxglove WebSocket client over the standard library (RFC 6455, client side).

Only what the tests need: the opening handshake with a subprotocol, text and binary frames
(unfragmented, as the server sends them), and masked text frames to subscribe.
"""

from __future__ import annotations

import base64
import hashlib
import json
import os
import socket
import struct
from typing import Any

#: The subprotocol foxglove-sdk 0.30 speaks (the older ws-protocol servers use foxglove.websocket.v1).
SUBPROTOCOL = "foxglove.sdk.v1"


class HandshakeRefused(ConnectionError):
    """The server answered the opening handshake with something other than 101."""

    def __init__(self, status_line: str, body: str) -> None:
        super().__init__(f"handshake refused: {status_line}: {body}")
        self.status_line, self.body = status_line, body


_GUID = "258EAFA5-E914-47DA-95CA-C5AB0DC85B11"


class FoxgloveClient:
    def __init__(
        self,
        host: str,
        port: int,
        *,
        timeout_s: float = 10.0,
        subprotocols: str | None = SUBPROTOCOL,
    ) -> None:
        self.sock = socket.create_connection((host, port), timeout=timeout_s)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (
                f"GET / HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
                f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                f"Sec-WebSocket-Version: 13\r\n"
                + (f"Sec-WebSocket-Protocol: {subprotocols}\r\n" if subprotocols else "")
                + "\r\n"
            ).encode()
        )
        self._buf = b""
        while b"\r\n\r\n" not in self._buf:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise ConnectionError("server closed during the handshake")
            self._buf += chunk
        head, self._buf = self._buf.split(b"\r\n\r\n", 1)
        lines = head.decode("latin-1").split("\r\n")
        if " 101 " not in lines[0]:
            self.sock.settimeout(1.0)
            try:
                while chunk := self.sock.recv(65536):
                    self._buf += chunk
            except OSError:
                pass
            raise HandshakeRefused(lines[0], self._buf.decode("utf-8", "replace").strip())
        headers = {k.strip().lower(): v.strip() for k, v in (x.split(":", 1) for x in lines[1:])}
        accept = base64.b64encode(hashlib.sha1((key + _GUID).encode()).digest()).decode()
        if headers.get("sec-websocket-accept") != accept:
            raise ConnectionError("bad Sec-WebSocket-Accept")
        self.subprotocol = headers.get("sec-websocket-protocol")

    def _exact(self, n: int) -> bytes:
        while len(self._buf) < n:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise ConnectionError("server closed the connection")
            self._buf += chunk
        out, self._buf = self._buf[:n], self._buf[n:]
        return out

    def frame(self) -> tuple[int, bytes]:
        """(opcode, payload) of the next data frame: 1 text, 2 binary (pings are skipped)."""
        while True:
            b0, b1 = self._exact(2)
            n = b1 & 0x7F
            if n == 126:
                n = struct.unpack(">H", self._exact(2))[0]
            elif n == 127:
                n = struct.unpack(">Q", self._exact(8))[0]
            payload = self._exact(n)
            opcode = b0 & 0x0F
            if opcode in (1, 2):
                return opcode, payload
            if opcode == 8:
                raise ConnectionError("server sent close")

    def json(self) -> dict[str, Any]:
        """The next text message (binary ones before it are skipped)."""
        while True:
            opcode, payload = self.frame()
            if opcode == 1:
                doc: dict[str, Any] = json.loads(payload)
                return doc

    def send_json(self, doc: dict[str, Any]) -> None:
        data = json.dumps(doc).encode()
        mask = os.urandom(4)
        if len(data) < 126:
            head = bytes([0x81, 0x80 | len(data)])
        else:
            head = bytes([0x81, 0x80 | 126]) + struct.pack(">H", len(data))
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))

    def message_data(self) -> tuple[int, int, bytes]:
        """The next messageData: (subscription id, log time ns, payload)."""
        while True:
            opcode, payload = self.frame()
            if opcode == 2 and payload[0] == 0x01:
                sub_id, log_time = struct.unpack_from("<IQ", payload, 1)
                return sub_id, log_time, payload[13:]

    def close(self) -> None:
        self.sock.close()
