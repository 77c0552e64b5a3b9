"""Typed topics over a transport, and request/result pairs with a correlation id.

Subscription handlers run on middleware threads; a malformed message is reported (logged and
counted in :attr:`Node.malformed`) and dropped, never raised into the middleware.
"""

from __future__ import annotations

import logging
import threading
import time
import uuid
from collections.abc import Callable
from typing import Any

from objsearch.runtime import messages as m
from objsearch.runtime.errors import MessageError, RobotError
from objsearch.runtime.qos import QoS
from objsearch.runtime.transport import Publisher, ServiceClient, Transport

log = logging.getLogger("objsearch.runtime")


class TypedPublisher:
    def __init__(self, pub: Publisher, msgtype: str) -> None:
        self._pub = pub
        self.msgtype = msgtype

    def publish(self, msg: Any) -> None:
        self._pub.publish(m.encode(msg, self.msgtype))


class TypedClient:
    def __init__(self, client: ServiceClient, service: str, srvtype: str) -> None:
        self._client = client
        self.service = service
        self.srvtype = srvtype

    def call(self, request: Any, timeout_s: float) -> Any | None:
        """The decoded response, or None when none came in time."""
        data = self._client.call(m.encode(request, f"{self.srvtype}_Request"), timeout_s)
        return None if data is None else m.decode(data, f"{self.srvtype}_Response")


class Node:
    def __init__(self, transport: Transport) -> None:
        self.transport = transport
        self.malformed: list[str] = []
        self._lock = threading.Lock()

    def publisher(self, topic: str, msgtype: str, qos: QoS) -> TypedPublisher:
        return TypedPublisher(self.transport.publisher(topic, msgtype, qos), msgtype)

    def subscribe(self, topic: str, msgtype: str, qos: QoS, handler: Callable[[Any], None]) -> None:
        def on_bytes(data: bytes) -> None:
            try:
                handler(m.decode(data, msgtype))
            except MessageError as exc:
                self.report(f"{topic}: {exc}")

        self.transport.subscribe(topic, msgtype, qos, on_bytes)

    def serve(
        self, service: str, srvtype: str, handler: Callable[[Any, Callable[[Any], None]], None]
    ) -> None:
        """``handler(request, respond)``: a malformed request is reported and left unanswered."""

        def on_bytes(data: bytes, respond_bytes: Callable[[bytes], None]) -> None:
            try:
                request = m.decode(data, f"{srvtype}_Request")
            except MessageError as exc:
                self.report(f"{service}: {exc}")
                return
            handler(request, lambda msg: respond_bytes(m.encode(msg, f"{srvtype}_Response")))

        self.transport.serve(service, srvtype, on_bytes)

    def client(self, service: str, srvtype: str) -> TypedClient:
        return TypedClient(self.transport.client(service, srvtype), service, srvtype)

    def report(self, problem: str) -> None:
        with self._lock:
            self.malformed.append(problem)
        log.warning("dropped a message: %s", problem)

    def close(self) -> None:
        self.transport.close()


class Requester:
    """Sends a JSON request on a String topic until its result (same ``id``) arrives.

    Sending again covers the moments before discovery has matched both ends; the server
    answers a repeated id from its cache, so a request is carried out once.
    """

    def __init__(self, node: Node, topic: str, result_topic: str, qos: QoS) -> None:
        self._pub = node.publisher(topic, m.STRING, qos)
        self._results: dict[str, dict[str, Any]] = {}
        self._cond = threading.Condition()
        node.subscribe(result_topic, m.STRING, qos, self._on_result)

    def _on_result(self, msg: Any) -> None:
        doc = m.json_of_string(msg)
        with self._cond:
            self._results[str(doc.get("id"))] = doc
            self._cond.notify_all()

    def call(
        self,
        body: dict[str, Any],
        *,
        timeout_s: float,
        resend_s: float = 0.5,
        what: str = "request",
    ) -> dict[str, Any]:
        rid = str(body.get("id") or uuid.uuid4())
        msg = m.json_string({**body, "id": rid})
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while rid not in self._results:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise RobotError(f"no answer to {what} {rid} within {timeout_s:g} s")
                self._pub.publish(msg)
                self._cond.wait(min(resend_s, left))
            return self._results.pop(rid)


class Server:
    """Answers JSON requests once per id, in arrival order, on the thread that calls :meth:`spin`."""

    def __init__(self, node: Node, topic: str, result_topic: str, qos: QoS) -> None:
        self._node = node
        self._pub = node.publisher(result_topic, m.STRING, qos)
        self._answers: dict[str, dict[str, Any]] = {}
        self._queue: list[dict[str, Any]] = []
        self._queued: set[str] = set()
        self._cond = threading.Condition()
        node.subscribe(topic, m.STRING, qos, self._on_request)

    def _on_request(self, msg: Any) -> None:
        doc = m.json_of_string(msg)
        rid = doc.get("id")
        if not isinstance(rid, str) or not rid:
            raise MessageError(f"a request without an id: {msg.data[:80]!r}")
        with self._cond:
            if rid in self._answers:
                self._pub.publish(m.json_string(self._answers[rid]))
            elif rid not in self._queued:
                self._queued.add(rid)
                self._queue.append(doc)
                self._cond.notify_all()

    def next(self, timeout_s: float) -> dict[str, Any] | None:
        with self._cond:
            if not self._queue:
                self._cond.wait(timeout_s)
            return self._queue.pop(0) if self._queue else None

    def answer(self, request: dict[str, Any], result: dict[str, Any]) -> None:
        doc = {**result, "id": request["id"]}
        with self._cond:
            self._answers[request["id"]] = doc
        self._pub.publish(m.json_string(doc))
