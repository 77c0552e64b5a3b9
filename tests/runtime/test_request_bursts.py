"""No request is lost over ``--transport ros2`` when other peers send a burst and leave (issue 43,
item 10).

The agent's request reader kept the last 10 requests (KEEP_LAST, ROS 2's default depth), and
rclpy's executor takes one message per callback, far slower than a burst arrives: a peer's burst
of tens of requests pushed the requests of other clients out of the reader's history before the
executor took them. (Cyclone, under ``--transport dds``, hands each sample to our listener on its
receive thread, so its reader never filled.) Everything here is in one process, each node in a
context (a DDS participant) of its own, so no timing of process start is involved; each round
interleaves one client's requests, each sent once, with three peers' bursts, then the peers
leave."""

from __future__ import annotations

import json
import threading
from typing import Any

import pytest

pytest.importorskip("rclpy")

from objsearch.runtime import messages as m
from objsearch.runtime.backends import open_transport
from objsearch.runtime.config import RuntimeConfig
from objsearch.runtime.node import Node, Server
from objsearch.runtime.requests import WhereRequest, parse_where_request
from objsearch.runtime.transport import Backend, TransportConfig

from .runtime_fixtures import STARTUP_S, next_domain

ROUNDS = 4
PEERS = 3
#: Each peer's burst; the client sends one request after every :data:`SPACING` of its messages.
BURST = 60
SPACING = 4
#: How long a round may take to be answered in full (it takes well under a second when nothing is
#: lost: a lost request is never answered, so this is only how long the test waits to say so).
ANSWER_S = 20.0


def _ros2(domain: int, name: str) -> Node:
    return Node(open_transport(TransportConfig(backend=Backend.ROS2, domain_id=domain, node=name)))


class Heard:
    """The ids of the results one client got."""

    def __init__(self) -> None:
        self.ids: set[str] = set()
        self._cond = threading.Condition()

    def __call__(self, msg: Any) -> None:
        with self._cond:
            self.ids.add(json.loads(msg.data)["id"])
            self._cond.notify_all()

    def wait_for(self, ids: set[str], timeout_s: float) -> set[str]:
        """The ids of ``ids`` not heard within ``timeout_s``."""
        with self._cond:
            self._cond.wait_for(lambda: ids <= self.ids, timeout_s)
            return ids - self.ids


def test_no_request_is_lost_when_peers_burst_and_leave() -> None:
    config = RuntimeConfig()
    topic, result, qos = config.topics.where, config.topics.where_result, config.qos.requests
    domain = next_domain()
    agent = _ros2(domain, "objsearch")
    server: Server[WhereRequest] = Server(agent, topic, result, qos, parse_where_request)
    stop = threading.Event()

    def answer() -> None:
        while not stop.is_set():
            request = server.next(0.1)
            if request is not None:
                server.answer(request, {"ok": False, "error": "a test answer"})

    answering = threading.Thread(target=answer, daemon=True)
    answering.start()
    client = _ros2(domain, "client")
    heard = Heard()
    client.subscribe(result, m.STRING, qos, heard)
    ask = client.publisher(topic, m.STRING, qos)

    def send(node_pub: Any, rid: str) -> None:
        node_pub.publish(m.json_string({"id": rid, "target": "Cup"}))

    lost: dict[int, set[str]] = {}
    try:
        # Discovery: the client's first request is sent until it is answered.
        send(ask, "hello")
        while heard.wait_for({"hello"}, 0.2):
            send(ask, "hello")
        graph = agent.transport.node  # type: ignore[attr-defined]
        for r in range(ROUNDS):
            peers = [_ros2(domain, f"peer_{r}_{i}") for i in range(PEERS)]
            try:
                pubs = [p.publisher(topic, m.STRING, qos) for p in peers]
                for p in peers:
                    p.subscribe(result, m.STRING, qos, lambda msg: None)
                deadline = threading.Event()
                timer = threading.Timer(STARTUP_S, deadline.set)
                timer.start()
                while graph.count_publishers(topic) < PEERS + 1 and not deadline.wait(0.02):
                    pass
                timer.cancel()
                assert not deadline.is_set(), "the peers never joined the graph"
                mine = set()
                for i in range(BURST):
                    for j, pub in enumerate(pubs):
                        send(pub, f"peer-{r}-{j}-{i}")
                    if i % SPACING == 0:
                        mine.add(f"client-{r}-{i}")
                        send(ask, f"client-{r}-{i}")
            finally:
                for p in peers:  # they leave right after their burst
                    p.close()
            missing = heard.wait_for(mine, ANSWER_S)
            if missing:
                lost[r] = missing
    finally:
        stop.set()
        answering.join()
        client.close()
        agent.close()
    sent = ROUNDS * len(range(0, BURST, SPACING))
    assert not lost, (
        f"{sum(map(len, lost.values()))} of {sent} requests never answered (by round: "
        f"{ {r: len(ids) for r, ids in lost.items()} }; requests QoS {qos})"
    )
