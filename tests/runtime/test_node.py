"""Request/result pairs on one real Zenoh session (in-process, loopback only): malformed requests
are answered or dropped, memory of answered ids stays bounded, a full queue says busy."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

pytest.importorskip("zenoh")

from objsearch.ros.qos import DEFAULT
from objsearch.runtime import messages as m
from objsearch.runtime.backends import open_transport
from objsearch.runtime.errors import RobotError
from objsearch.runtime.node import Node, Requester, Server
from objsearch.runtime.requests import parse_find_request, parse_open_result
from objsearch.runtime.transport import TransportConfig


@pytest.fixture
def node() -> Iterator[Node]:
    n = Node(open_transport(TransportConfig(connect=(), listen=("tcp/127.0.0.1:0",))))
    yield n
    n.close()


class Answers:
    def __init__(self, node: Node, topic: str) -> None:
        self.docs: list[dict[str, Any]] = []
        self._cond = threading.Condition()
        node.subscribe(topic, m.STRING, DEFAULT, self._on)

    def _on(self, msg: Any) -> None:
        with self._cond:
            self.docs.append(json.loads(msg.data))
            self._cond.notify_all()

    def wait(self, n: int, timeout_s: float = 10.0) -> list[dict[str, Any]]:
        with self._cond:
            assert self._cond.wait_for(lambda: len(self.docs) >= n, timeout_s), self.docs
            return list(self.docs)


def until(check: Callable[[], bool], timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not check():
        assert time.monotonic() < deadline
        time.sleep(0.02)


def test_answered_ids_are_a_bounded_lru(node: Node) -> None:
    server = Server(node, "/q", "/q/result", DEFAULT, parse_find_request, remember=8)
    answers = Answers(node, "/q/result")
    pub = node.publisher("/q", m.STRING, DEFAULT)
    time.sleep(0.2)
    for i in range(50):
        pub.publish(m.json_string({"id": f"r{i}", "target": "Apple", "scene": "abc"}))
    docs = answers.wait(50)
    assert [d["id"] for d in docs] == [f"r{i}" for i in range(50)]
    assert all(not d["ok"] and "field 'scene'" in d["error"] for d in docs)
    assert server.remembered() == 8 and server.refused == 50
    pub.publish(m.json_string({"id": "r49", "target": "Apple", "scene": "abc"}))
    assert answers.wait(51)[-1]["id"] == "r49"
    assert server.refused == 50  # answered from memory
    pub.publish(m.json_string({"id": "r0", "target": "Apple", "scene": "abc"}))
    assert answers.wait(52)[-1]["id"] == "r0"
    assert server.refused == 51  # forgotten, so checked again
    assert server.remembered() == 8


def test_a_full_queue_answers_busy_and_a_served_request_is_answered_once(node: Node) -> None:
    server = Server(node, "/q", "/q/result", DEFAULT, parse_find_request, max_queued=2)
    answers = Answers(node, "/q/result")
    pub = node.publisher("/q", m.STRING, DEFAULT)
    time.sleep(0.2)
    for i in range(4):
        pub.publish(m.json_string({"id": f"v{i}", "target": "Apple"}))
    busy = answers.wait(2)
    assert {d["id"] for d in busy} == {"v2", "v3"}
    assert all(d["error"].startswith("busy") for d in busy)
    first = server.next(5)
    assert first is not None and first.id == "v0"
    pub.publish(m.json_string({"id": "v1", "target": "Apple"}))  # sent again while queued
    second = server.next(5)
    assert second is not None and second.id == "v1"
    assert server.next(0.3) is None
    server.answer(first, {"ok": True})
    assert answers.wait(3)[-1] == {"id": "v0", "ok": True}


def test_unanswerable_messages_are_dropped_with_a_report(node: Node) -> None:
    Server(node, "/q", "/q/result", DEFAULT, parse_find_request)
    raw = node.transport.publisher("/q", m.STRING, DEFAULT)
    time.sleep(0.2)
    for data in [b"", b"\x00\x01\x00\x00\xff\xff\xff\xff", b"\x00\x07\x00\x00abcd", b"\x00" * 9]:
        raw.publish(data)
    for text in ["[1]", '{"target": "Apple"}', '{"id": 5}', "[" * 3000 + "]" * 3000, "x" * 20_000]:
        raw.publish(m.encode(m.string(text), m.STRING))
    until(lambda: node.dropped == 9)
    assert all(problem.startswith("/q: ") for problem in node.malformed)


def test_requester_drops_a_malformed_result_and_keeps_waiting(node: Node) -> None:
    requester = Requester(node, "/o", "/o/result", DEFAULT, parse_open_result)
    results = node.publisher("/o/result", m.STRING, DEFAULT)

    def robot(msg: Any) -> None:
        rid = json.loads(msg.data)["id"]
        results.publish(m.json_string({"id": rid, "ok": True, "stamp_ns": "soon", "yaw": 0}))
        results.publish(m.json_string({"id": "someone-else", "ok": True}))
        results.publish(m.json_string({"id": rid, "ok": True, "stamp_ns": 7, "yaw": 0.5}))

    node.subscribe("/o", m.STRING, DEFAULT, robot)
    time.sleep(0.2)
    result = requester.call({"id": "open-1", "static_id": "x"}, timeout_s=10, resend_s=5)
    assert (result.ok, result.stamp_ns, result.yaw) == (True, 7, 0.5)
    assert any("field 'stamp_ns'" in p for p in node.malformed)
    with pytest.raises(RobotError, match="no answer"):
        Requester(node, "/silent", "/silent/result", DEFAULT, parse_open_result).call(
            {"static_id": "x"}, timeout_s=0.3
        )
