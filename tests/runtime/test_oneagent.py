"""One agent per robot (issue 43, item 9): a second agent on the robot's ROS domain refuses to
serve, naming the first; two started at the same moment agree on which one serves.

The rules are tried in one process on real rclpy nodes (each in a context, a DDS participant, of
its own), against another agent or a node sending heartbeats we write, waiting for the graph to
match rather than for time; then ``objsearch agent run`` itself, as processes, over ``ros2`` and
``dds``."""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("rclpy")

from objsearch.ros.qos import DEFAULT
from objsearch.runtime import messages as m
from objsearch.runtime.backends import open_transport
from objsearch.runtime.client import AgentClient
from objsearch.runtime.config import RuntimeConfig, Timeouts
from objsearch.runtime.errors import AnotherAgentError
from objsearch.runtime.node import Node
from objsearch.runtime.oneagent import OneAgent, serves
from objsearch.runtime.requests import Heartbeat
from objsearch.runtime.transport import Backend, TransportConfig

from .runtime_fixtures import STARTUP_S, Net, next_domain, objsearch, stop
from .searches import client_config


def until(condition: Callable[[], bool], what: str, timeout_s: float = STARTUP_S) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, f"not within {timeout_s} s: {what}"
        time.sleep(0.02)


#: The claim of the agents tried in process: they claim once the graph has matched them, so a
#: second is ample (an agent's own, 5 s, covers discovery too).
CLAIM_S = 1.0


def config(domain: int, name: str = "objsearch", claim_s: float = CLAIM_S) -> RuntimeConfig:
    return RuntimeConfig(
        transport=TransportConfig(Backend.ROS2, domain_id=domain, node=name),
        timeouts=Timeouts(claim_s=claim_s),
    )


@contextmanager
def ros2_node(domain: int, name: str) -> Iterator[Node]:
    node = Node(open_transport(config(domain, name).transport))
    try:
        yield node
    finally:
        node.close()


@contextmanager
def agent(domain: int, name: str, log: Path, claim_s: float = CLAIM_S) -> Iterator[OneAgent]:
    with ros2_node(domain, name) as node:
        one = OneAgent(node, config(domain, name, claim_s), log)
        try:
            yield one
        finally:
            one.close()


def heartbeats_seen(one: OneAgent) -> int:
    """How many publishers the agent's node sees on the heartbeat topic (its own included)."""
    graph: Any = one._node.transport.node  # type: ignore[attr-defined]
    return int(graph.count_publishers(RuntimeConfig().topics.agents))


class Forger:
    """A node of its own sending the heartbeats it is given, four times a second."""

    def __init__(self, node: Node, *beats: dict[str, Any]) -> None:
        self._pub = node.publisher(RuntimeConfig().topics.agents, m.STRING, DEFAULT)
        self.beats = list(beats)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(0.25):
            for beat in self.beats:
                self._pub.publish(m.json_string(beat))

    def close(self) -> None:
        self._stop.set()
        self._thread.join()


def beat(state: str, since_ns: int, **changes: Any) -> dict[str, Any]:
    other = Heartbeat(
        agent="ab" * 16,
        node="objsearch",
        host="robot-pc",
        pid=4242,
        log="/var/log/objsearch",
        state=state,
        since_ns=since_ns,
        serves=serves(RuntimeConfig()),
    )
    return dataclasses.replace(other, **changes).to_json()


@pytest.mark.parametrize(
    ("state", "since_ns"), [("serving", 1), ("claiming", 1)], ids=["serving", "claiming-first"]
)
def test_an_agent_refuses_a_robot_another_agent_serves_or_claimed_first(
    tmp_path: Path, state: str, since_ns: int
) -> None:
    domain = next_domain()
    with (
        agent(domain, "objsearch", tmp_path / "log") as one,
        ros2_node(domain, "other") as other,
    ):
        forger = Forger(other, beat(state, since_ns))
        try:
            until(lambda: heartbeats_seen(one) == 2, "the other agent's heartbeats matched")
            # Heard before the claim: the outcome is the rule's, not whether a heartbeat came
            # within CLAIM_S on a busy machine (this test failed once in 5 runs under load, its
            # message not kept; that wait was the one timing it depended on).
            until(lambda: one.rival is not None, "the other agent's heartbeat heard")
            with pytest.raises(AnotherAgentError) as refused:
                one.claim()
        finally:
            forger.close()
    text = str(refused.value)
    assert text.startswith(
        f"another agent {'serves this robot' if state == 'serving' else 'claimed this robot first'}"
        f" on ROS domain {domain} over ros2: node 'objsearch' (agent {'ab' * 16}, pid 4242 on "
        "robot-pc, log '/var/log/objsearch')"
    ), text
    assert f"this agent (pid {one.me.pid}, log '{tmp_path / 'log'}') will not serve" in text
    assert one.me.state == "claiming"


def test_an_agent_serves_past_a_later_claim_and_another_robots_agent(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A claim that came later yields to this one; an agent serving other names is another
    robot's; a heartbeat that is not one is dropped, never taken for an agent."""
    domain = next_domain()
    later = beat("claiming", time.time_ns() + 10**12)
    elsewhere = beat("serving", 1, agent="cd" * 16, serves=("/robot2/find", "/robot2/goal_pose"))
    with (
        caplog.at_level(logging.WARNING, "objsearch.runtime"),
        agent(domain, "objsearch", tmp_path / "log") as one,
        ros2_node(domain, "other") as other,
    ):
        forger = Forger(other, elsewhere, {"agent": "no"}, beat("serving", 1, pid=-1), later)
        try:
            until(lambda: heartbeats_seen(one) == 2, "the other heartbeats matched")
            one.claim()
            assert one.me.state == "serving"
            until(lambda: "ab" * 16 in caplog.text, "the later claim noticed")
            time.sleep(4 * one.period_s)  # more heartbeats of both kinds arrive
            assert one.rival is None
            assert one._node.dropped >= 2  # the two that are not heartbeats
        finally:
            forger.close()
    assert "another agent of this robot is on" in caplog.text
    assert "it will not serve (this agent " in caplog.text  # came first, or is serving
    assert "cd" * 16 not in caplog.text


def test_a_serving_agent_that_meets_an_earlier_one_stops(tmp_path: Path) -> None:
    """Two agents that both serve (they met after their claims): the later claim stops."""
    domain = next_domain()
    with (
        agent(domain, "objsearch", tmp_path / "log") as one,
        ros2_node(domain, "other") as other,
    ):
        one.claim()  # alone on the domain
        assert one.me.state == "serving"
        forger = Forger(other, beat("serving", one.me.since_ns + 10**9))
        try:
            until(lambda: heartbeats_seen(one) == 2, "the other agent matched")
            time.sleep(4 * one.period_s)
            assert one.rival is None  # it serves since later: it yields, not this one
            forger.beats = [beat("serving", one.me.since_ns - 1)]
            until(lambda: one.rival is not None, "the earlier agent heard")
        finally:
            forger.close()
    assert "stops serving" in str(one.refusal())


def test_an_idle_serving_agent_that_hears_an_earlier_claim_stops(tmp_path: Path) -> None:
    """An agent claiming the robot since before this one began (heard only now: discovery was
    slow, or the two parts of the network joined) comes first, serving or not: the serving agent
    yields to it at once."""
    domain = next_domain()
    with (
        agent(domain, "objsearch", tmp_path / "log") as one,
        ros2_node(domain, "other") as other,
    ):
        one.claim()  # alone on the domain
        assert one.me.state == "serving"
        forger = Forger(other, beat("claiming", one.me.since_ns - 1))
        try:
            until(lambda: heartbeats_seen(one) == 2, "the other agent matched")
            until(lambda: one.rival is not None, "the earlier claim heard", timeout_s=20 * CLAIM_S)
        finally:
            forger.close()
    text = str(one.refusal())
    assert text.startswith("another agent claimed this robot first on "), text
    assert f"agent {'ab' * 16}" in text and "stops serving" in text, text


def test_a_claim_waits_until_a_later_agent_serving_the_robot_has_stopped(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """The later agent stops once it hears this one (the test above); until its heartbeats say
    it no longer serves, this one does not begin, so the robot is never driven by both."""
    domain = next_domain()
    claim_s = 3.0  # a later heartbeat missing for this long reads as stopped
    with (
        caplog.at_level(logging.WARNING, "objsearch.runtime"),
        agent(domain, "objsearch", tmp_path / "log", claim_s) as one,
        ros2_node(domain, "other") as other,
    ):
        forger = Forger(other, beat("serving", time.time_ns() + 10**12))
        claimed = threading.Event()
        try:
            until(lambda: heartbeats_seen(one) == 2, "the other agent matched")

            def claim() -> None:
                one.claim()
                claimed.set()

            thread = threading.Thread(target=claim, daemon=True)
            thread.start()
            assert not claimed.wait(2 * claim_s), "began while the later agent still served"
            assert "this agent serves once the later one has stopped" in caplog.text
        finally:
            forger.close()
        thread.join(STARTUP_S)
        assert claimed.is_set() and one.me.state == "serving" and one.rival is None


def test_two_agents_claiming_at_once_agree_on_one(tmp_path: Path) -> None:
    domain = next_domain()
    with (
        agent(domain, "objsearch", tmp_path / "a") as a,
        agent(domain, "objsearch", tmp_path / "b") as b,
    ):
        until(lambda: heartbeats_seen(a) == heartbeats_seen(b) == 2, "both matched")
        outcome: dict[str, str] = {}

        def claim(name: str, one: OneAgent) -> None:
            try:
                one.claim()
                outcome[name] = "serving"
            except AnotherAgentError as exc:
                outcome[name] = str(exc)

        threads = [threading.Thread(target=claim, args=x) for x in (("a", a), ("b", b))]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        first, second = ("a", "b") if a.me.key() < b.me.key() else ("b", "a")
        assert outcome[first] == "serving", outcome
        assert f"agent {(a if first == 'a' else b).me.agent}" in outcome[second], outcome
        assert "claimed this robot first" in outcome[second]


@pytest.mark.parametrize("transport", ["ros2", "dds"])
def test_agent_run_refuses_a_robot_another_agent_serves(transport: str, tmp_path: Path) -> None:
    """Two ``agent run`` started together on one domain: one exits 2 naming the other, which
    answers; a third started later exits 2 naming the one serving. An agent that refused during
    its claim never opened its log."""
    net = Net(transport, ["--transport", transport, "--domain-id", str(next_domain())])

    def run(name: str) -> Any:
        log = tmp_path / name
        return objsearch("agent", "run", *net.args, "--log", str(log), log=tmp_path / f"{name}.txt")

    procs = {"a": run("a"), "b": run("b")}
    try:
        until(lambda: any(p.poll() is not None for p in procs.values()), "one agent refused")
        loser = next(n for n, p in procs.items() if p.poll() is not None)
        winner = "b" if loser == "a" else "a"
        assert procs[loser].returncode == 2
        text = (tmp_path / f"{loser}.txt").read_text()
        assert "objsearch: error: another agent " in text, text
        assert f"pid {procs[winner].pid} on " in text, text
        # Started together, they may find each other after both claims (Fast DDS takes up to
        # its 3 s announcement period; under load the later claim may also end first): then
        # the later claim stops serving, and still only one serves.
        assert "will not serve" in text or "stops serving" in text, text
        served = "stops serving" in text  # it had opened its log
        with AgentClient(client_config(net)) as client:
            assert client.where("Cup", timeout_s=STARTUP_S)["ok"]
        procs["c"] = run("c")
        assert procs["c"].wait(STARTUP_S) == 2
        text = (tmp_path / "c.txt").read_text()
        assert "objsearch: error: another agent serves this robot" in text, text
        assert f"pid {procs[winner].pid} on " in text, text
        assert procs[winner].poll() is None
        assert (tmp_path / loser).exists() == served and not (tmp_path / "c").exists()
    finally:
        codes = {n: stop(p) for n, p in procs.items()}
    assert codes[winner] == 0
    assert "Traceback" not in "".join((tmp_path / f"{n}.txt").read_text() for n in procs)


@pytest.mark.parametrize("transport", ["ros2", "dds"])
def test_agent_run_serving_and_idle_stops_at_an_earlier_claim(
    transport: str, tmp_path: Path
) -> None:
    """``agent run`` serving, idle, hears an agent whose claim began before its own: it stops
    without waiting for a search and exits 2 naming that agent. Over ``dds`` this agent writes
    its heartbeats while another's come in, which hung the process before (issue 43 item 9)."""
    domain = next_domain()
    robot = tmp_path / "robot.toml"
    robot.write_text("[timeouts]\nclaim_s = 1.0\n")
    net = Net(transport, ["--transport", transport, "--domain-id", str(domain)])
    before = time.time_ns()
    log = tmp_path / "agent.txt"
    proc = objsearch(
        "agent", "run", *net.args, "--config", str(robot), "--log", str(tmp_path / "a"), log=log
    )
    try:
        with AgentClient(client_config(net)) as client:
            assert client.where("Cup", timeout_s=STARTUP_S)["ok"]  # serving
            forger = Forger(client.node, beat("claiming", before))  # a process has one participant
            try:
                assert proc.wait(STARTUP_S) == 2
            finally:
                forger.close()
    finally:
        stop(proc)
    text = log.read_text()
    assert "objsearch: error: another agent claimed this robot first on " in text, text
    assert f"agent {'ab' * 16}" in text and "stops serving" in text, text
    assert "Traceback" not in text
