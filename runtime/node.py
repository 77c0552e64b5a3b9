"""Typed topics over a transport, and request/result pairs with a correlation id.

Subscription handlers run on middleware threads; a malformed message (too big, bytes that are not
CDR of the topic's type, a field out of range) is reported — logged as ``dropped a message: …``
and counted in :attr:`Node.dropped` — and dropped, never raised into the middleware. A request
that can be answered (it has an ``id``) but is malformed gets an error result instead
(:class:`Server`).
"""

from __future__ import annotations

import logging
import threading
import time
import uuid
from collections import OrderedDict, deque
from collections.abc import Callable, Mapping
from typing import Any, Generic, Protocol, TypeVar

from objsearch.ros.qos import QoS
from objsearch.runtime import messages as m
from objsearch.runtime import requests as rq
from objsearch.runtime.errors import MessageError, RobotError
from objsearch.runtime.transport import Publisher, ServiceClient, Transport

log = logging.getLogger("objsearch.runtime")

#: The largest message any subscription decodes (a Detection2DArray of a busy view is tens of
#: kilobytes); bigger ones are dropped unread.
MAX_MESSAGE_BYTES = 4 * 1024 * 1024
#: Request and result topics carry one small JSON document (CDR header and length included).
MAX_REQUEST_BYTES = rq.MAX_DOCUMENT_BYTES + 64
#: Answers a :class:`Server` remembers (the last this many ids): a request sent again within
#: them is answered from memory, not carried out twice. Clients resend only until answered.
REMEMBER_IDS = 1024
#: Requests waiting to be carried out; more are answered ``busy`` at once (and may be resent).
MAX_QUEUED = 64


class TypedPublisher:
    def __init__(self, pub: Publisher, msgtype: str) -> None:
        self._pub = pub
        self.msgtype = msgtype

    def publish(self, msg: Any) -> None:
        self._pub.publish(m.encode(msg, self.msgtype))


class TypedClient:
    def __init__(self, client: ServiceClient, service: str, srvtype: str) -> None:
        self._client = client
        self.transport_client = client
        self.service = service
        self.srvtype = srvtype

    def call(self, request: Any, timeout_s: float) -> Any | None:
        """The decoded response, or None when none came in time."""
        data = self._client.call(m.encode(request, f"{self.srvtype}_Request"), timeout_s)
        return None if data is None else m.decode(data, f"{self.srvtype}_Response")


class Node:
    def __init__(self, transport: Transport) -> None:
        self.transport = transport
        self.malformed: deque[str] = deque(maxlen=100)  # the latest problems, for tests and logs
        self.dropped = 0
        #: Every topic this node reads, with the type it reads (for the agent's diagnosis).
        self.subscriptions: dict[str, str] = {}
        self._lock = threading.Lock()

    def publisher(self, topic: str, msgtype: str, qos: QoS) -> TypedPublisher:
        return TypedPublisher(self.transport.publisher(topic, msgtype, qos), msgtype)

    def subscribe(
        self,
        topic: str,
        msgtype: str,
        qos: QoS,
        handler: Callable[[Any], None],
        *,
        max_bytes: int = MAX_MESSAGE_BYTES,
    ) -> None:
        """``handler(message)`` on a middleware thread; it raises :class:`MessageError` to have a
        message reported and dropped."""

        def take(data: bytes) -> None:
            if len(data) > max_bytes:
                raise MessageError(f"{len(data)} bytes (at most {max_bytes} on this topic)")
            handler(m.decode(data, msgtype))

        def on_bytes(data: bytes) -> None:
            self._guarded(topic, lambda: take(data))

        self.subscriptions[topic] = msgtype
        self.transport.subscribe(topic, msgtype, qos, on_bytes)

    def diagnosis(self) -> list[str]:
        """What this node can tell is wrong on the graph, one sentence each: a publisher of a
        topic it reads whose type is not the one it reads (nothing it sends arrives), a QoS
        mismatch the middleware reported, and messages dropped as malformed. What the transport
        cannot see (zenoh and dds show no other nodes' types) is not named."""
        out: list[str] = []
        types_of = getattr(self.transport, "publisher_types", None)
        if types_of is not None:
            for topic, msgtype in sorted(self.subscriptions.items()):
                wrong = [(node, t) for node, t in types_of(topic) if t != msgtype]
                out.extend(
                    f"{topic} has a publisher of {t} (node {node}), which this agent does not "
                    f"read: it reads {msgtype}"
                    for node, t in wrong
                )
        mismatches: dict[str, str] = getattr(self.transport, "qos_mismatches", {})
        out.extend(text for _, text in sorted(mismatches.items()))
        with self._lock:
            if self.dropped:
                out.append(
                    f"{self.dropped} messages dropped as malformed, the latest: "
                    f"{self.malformed[-1]}"
                )
        return out

    def serve(
        self, service: str, srvtype: str, handler: Callable[[Any, Callable[[Any], None]], None]
    ) -> None:
        """``handler(request, respond)``: a malformed request is reported and left unanswered."""

        def take(data: bytes, respond_bytes: Callable[[bytes], None]) -> None:
            if len(data) > MAX_MESSAGE_BYTES:
                raise MessageError(f"{len(data)} bytes (at most {MAX_MESSAGE_BYTES})")
            request = m.decode(data, f"{srvtype}_Request")
            handler(request, lambda msg: respond_bytes(m.encode(msg, f"{srvtype}_Response")))

        def on_bytes(data: bytes, respond_bytes: Callable[[bytes], None]) -> None:
            self._guarded(service, lambda: take(data, respond_bytes))

        self.transport.serve(service, srvtype, on_bytes)

    def _guarded(self, name: str, call: Callable[[], None]) -> None:
        """``call()`` on a middleware thread: a :class:`MessageError` is reported (the message
        is dropped), any other error logged with its traceback and reported."""
        try:
            call()
        except MessageError as exc:
            self.report(f"{name}: {exc}")
        except Exception as exc:  # boundary: a handler's bug must never take the middleware down
            log.exception("%s: handler failed", name)
            self.report(f"{name}: {type(exc).__name__}: {exc}")

    def client(self, service: str, srvtype: str) -> TypedClient:
        return TypedClient(self.transport.client(service, srvtype), service, srvtype)

    def report(self, problem: str) -> None:
        with self._lock:
            self.malformed.append(problem)
            self.dropped += 1
        log.warning("dropped a message: %s", problem)

    def close(self) -> None:
        self.transport.close()


R = TypeVar("R")


class Requester(Generic[R]):
    """Sends a JSON request on a String topic until its result (same ``id``) arrives.

    Sending again covers the moments before discovery has matched both ends; the server
    answers a repeated id from its cache, so a request is carried out once. Results are checked
    by ``parse`` (:mod:`objsearch.runtime.requests`); one that fails, or answers an id nobody
    here is waiting for, is dropped with a log line.
    """

    def __init__(
        self,
        node: Node,
        topic: str,
        result_topic: str,
        qos: QoS,
        parse: Callable[[Mapping[str, Any]], R],
    ) -> None:
        self._node = node
        self._pub = node.publisher(topic, m.STRING, qos)
        self._parse = parse
        self._waiting: set[str] = set()
        self._results: dict[str, R] = {}
        self._cond = threading.Condition()
        node.subscribe(result_topic, m.STRING, qos, self._on_result, max_bytes=MAX_REQUEST_BYTES)

    def _on_result(self, msg: Any) -> None:
        doc = rq.parse_document(msg.data)
        rid = rq.request_id(doc)
        with self._cond:
            if rid not in self._waiting:
                return  # another client's answer (results share the topic), or a late repeat
        result = self._parse(doc)
        with self._cond:
            if rid in self._waiting:
                self._results[rid] = result
                self._cond.notify_all()

    def call(
        self,
        body: dict[str, Any],
        *,
        timeout_s: float,
        resend_s: float = 0.5,
        what: str = "request",
    ) -> R:
        rid = str(body.get("id") or uuid.uuid4())
        msg = m.json_string({**body, "id": rid})
        deadline = time.monotonic() + timeout_s
        with self._cond:
            self._waiting.add(rid)
            try:
                while rid not in self._results:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        raise RobotError(f"no answer to {what} {rid} within {timeout_s:g} s")
                    self._pub.publish(msg)
                    self._cond.wait(min(resend_s, left))
                return self._results.pop(rid)
            finally:
                self._waiting.discard(rid)
                self._results.pop(rid, None)


class HasId(Protocol):
    @property
    def id(self) -> str: ...


Q = TypeVar("Q", bound=HasId)


class Server(Generic[Q]):
    """Answers JSON requests once per id, in arrival order, on the thread that calls :meth:`next`.

    Each request is checked by ``parse`` on arrival: one without a usable id is dropped with a
    log line (there is nothing to answer it under); one with an id and a bad field is answered
    at once ``{id, ok: false, error}``, the error naming the field. The last
    :data:`REMEMBER_IDS` answers are kept (least recently used out first), so memory stays
    bounded however many ids arrive; at most :data:`MAX_QUEUED` requests wait, more are answered
    ``busy``.
    """

    def __init__(
        self,
        node: Node,
        topic: str,
        result_topic: str,
        qos: QoS,
        parse: Callable[[Mapping[str, Any]], Q],
        *,
        remember: int = REMEMBER_IDS,
        max_queued: int = MAX_QUEUED,
    ) -> None:
        self._node = node
        self._topic = topic
        self._parse = parse
        self._remember = remember
        self._max_queued = max_queued
        self._pub = node.publisher(result_topic, m.STRING, qos)
        self._answers: OrderedDict[str, dict[str, Any]] = OrderedDict()
        self._queue: deque[Q] = deque()
        self._queued: set[str] = set()
        self._cond = threading.Condition()
        self.refused = 0
        node.subscribe(topic, m.STRING, qos, self._on_request, max_bytes=MAX_REQUEST_BYTES)

    def _on_request(self, msg: Any) -> None:
        doc = rq.parse_document(msg.data)
        rid = rq.request_id(doc)
        with self._cond:
            if rid in self._answers:
                self._answers.move_to_end(rid)
                self._pub.publish(m.json_string(self._answers[rid]))
                return
            if rid in self._queued:
                return  # sent again while waiting: it will be answered once
            try:
                request = self._parse(doc)
            except MessageError as exc:
                self.refused += 1
                log.warning("%s: refused request %s: %s", self._topic, rid, exc)
                self._remember_answer({"id": rid, "ok": False, "error": str(exc)})
                return
            if len(self._queue) >= self._max_queued:
                log.warning("%s: busy, refused request %s", self._topic, rid)
                error = f"busy: {len(self._queue)} requests are waiting; send it again later"
                self._pub.publish(m.json_string({"id": rid, "ok": False, "error": error}))
                return
            self._queued.add(rid)
            self._queue.append(request)
            self._cond.notify_all()

    def _remember_answer(self, doc: dict[str, Any]) -> None:
        """Under the lock: keep ``doc`` as the answer to its id, and publish it."""
        self._answers[doc["id"]] = doc
        self._answers.move_to_end(doc["id"])
        while len(self._answers) > self._remember:
            self._answers.popitem(last=False)
        self._pub.publish(m.json_string(doc))

    def next(self, timeout_s: float) -> Q | None:
        with self._cond:
            if not self._queue:
                self._cond.wait(timeout_s)
            return self._queue.popleft() if self._queue else None

    def answer(self, request: Q, result: dict[str, Any]) -> None:
        with self._cond:
            self._queued.discard(request.id)
            self._remember_answer({**result, "id": request.id})

    def remembered(self) -> int:
        with self._cond:
            return len(self._answers)
