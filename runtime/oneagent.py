"""One agent per robot: an agent that finds another agent serving its robot refuses to serve.

Two agents on one ROS domain both hear every find request and both drive the robot. So each
agent says who it is on a topic of its own (``/objsearch/agents``, :class:`Heartbeat` as JSON,
several times a second) and listens there. Two agents are of the same robot when their
``serves`` (the find topic and where goals go) share a name. Between two such agents the
**earlier claim serves**: the earlier ``since_ns``, then the smaller id (:meth:`Heartbeat.key`),
whatever state either is in, so every agent applies the same rule to the same two heartbeats
and the outcome does not depend on which process got further first.

At start-up an agent *claims* the robot for ``[timeouts] claim_s`` (5 s) before it opens its log
or takes a request: hearing an agent whose claim came first (serving or still claiming), it
refuses with :class:`AnotherAgentError` naming that agent. Hearing a *later* agent that already
serves (the two found each other late), it lets that one stop first: its claim ends only once no
such agent has been heard for ``claim_s``. While serving it keeps listening: an agent whose claim
came first, heard at any time, makes it stop — at once when idle, after the search it is in
otherwise (:attr:`OneAgent.rival`; :class:`~objsearch.runtime.agent_node.AgentNode` polls it) —
and it keeps sending ``serving`` until it has stopped (:meth:`OneAgent.close`), so the earlier
agent does not begin while it still drives the robot.

Works on every transport (a topic like any other). Not detected: an agent that sends no
heartbeats (before this module), and one on another domain or middleware that cannot hear ours.
The order of claims is read from the hosts' clocks: agents on two hosts need their clocks in
step (NTP), or the one whose clock is behind counts as the earlier.
"""

from __future__ import annotations

import dataclasses
import datetime
import logging
import os
import socket
import threading
import time
import uuid
from pathlib import Path
from typing import Any

from objsearch.ros.qos import DEFAULT
from objsearch.runtime import messages as m
from objsearch.runtime import requests as rq
from objsearch.runtime.config import RuntimeConfig
from objsearch.runtime.errors import AnotherAgentError, RuntimeConfigError
from objsearch.runtime.node import MAX_REQUEST_BYTES, Node

log = logging.getLogger("objsearch.runtime")

#: Heartbeats per claim window (at least every :data:`MAX_PERIOD_S`): one lost or sent before the
#: other agent matched is followed by more.
BEATS_PER_CLAIM = 8
MAX_PERIOD_S = 0.25
MIN_CLAIM_S, MAX_CLAIM_S = 0.1, 600.0


def serves(config: RuntimeConfig) -> tuple[str, ...]:
    """The names an agent serves: its find topic and where its robot's goals go."""
    goal = (
        config.navigation.action
        if config.navigation.interface == "navigate_to_pose"
        else config.topics.goal
    )
    return (config.topics.find, goal)


def _host() -> str:
    host = socket.gethostname()
    return host if rq.NAME_PATTERN.fullmatch(host) else "unknown-host"


def describe(other: rq.Heartbeat) -> str:
    since = datetime.datetime.fromtimestamp(other.since_ns / 1e9, datetime.UTC)
    return (
        f"node {other.node!r} (agent {other.agent}, pid {other.pid} on {other.host}, log "
        f"{other.log!r}), {'serving' if other.state == 'serving' else 'claiming it'} since "
        f"{since:%Y-%m-%d %H:%M:%S} UTC"
    )


class OneAgent:
    """This agent's claim on its robot: heartbeats out, other agents' heartbeats in."""

    def __init__(self, node: Node, config: RuntimeConfig, log_dir: Path) -> None:
        claim_s = config.timeouts.claim_s
        if not MIN_CLAIM_S <= claim_s <= MAX_CLAIM_S:
            raise RuntimeConfigError(
                f"[timeouts] claim_s must be {MIN_CLAIM_S:g}-{MAX_CLAIM_S:g} s, got {claim_s:g}"
            )
        self.claim_s = claim_s
        self.period_s = min(MAX_PERIOD_S, claim_s / BEATS_PER_CLAIM)
        self.where = (
            f"ROS domain {config.transport.domain_id} over {config.transport.backend.value}"
        )
        self.me = rq.Heartbeat(
            agent=uuid.uuid4().hex,
            node=config.transport.node,
            host=_host(),
            pid=os.getpid(),
            log=str(log_dir)[: rq.MAX_TEXT_CHARS],
            state="claiming",
            since_ns=time.time_ns(),
            serves=serves(config),
        )
        self._cond = threading.Condition()
        self._rival: rq.Heartbeat | None = None
        self._heard: set[str] = set()
        #: Agents of this robot that claimed later but serve, by id: when one was last heard
        #: (time.monotonic()). A claim ends only once none was heard for ``claim_s``.
        self._later_serving: dict[str, float] = {}
        self._beating = threading.Event()
        self._closed = threading.Event()
        self._pub = node.publisher(config.topics.agents, m.STRING, DEFAULT)
        self._node = node
        node.subscribe(
            config.topics.agents, m.STRING, DEFAULT, self._on_heartbeat, max_bytes=MAX_REQUEST_BYTES
        )
        self._thread = threading.Thread(target=self._beat, name="heartbeat", daemon=True)

    @property
    def rival(self) -> rq.Heartbeat | None:
        """The agent this one yields to, once it has heard one."""
        with self._cond:
            return self._rival

    def _yields_to(self, other: rq.Heartbeat) -> bool:
        """Under the lock. The earlier claim serves, in either state: :meth:`Heartbeat.key`."""
        return other.key() < self.me.key()

    def _on_heartbeat(self, msg: Any) -> None:
        other = rq.parse_heartbeat(rq.parse_document(msg.data))
        if other.agent == self.me.agent or not set(other.serves) & set(self.me.serves):
            return
        with self._cond:
            if self._rival is not None:
                return
            if self._yields_to(other):
                self._rival = other
                self._cond.notify_all()
                return
            if other.state == "serving":
                self._later_serving[other.agent] = time.monotonic()
                self._cond.notify_all()
            first = other.agent not in self._heard
            self._heard.add(other.agent)
            serving = self.me.state == "serving"
        if first:
            log.warning(
                "another agent of this robot is on %s: %s; it %s (this agent %s)",
                self.where,
                describe(other),
                "stops serving" if other.state == "serving" else "will not serve",
                "is serving" if serving else "came first",
            )

    def _beat(self) -> None:
        while not self._closed.is_set():
            with self._cond:
                # A claim that yields goes quiet at once; a serving agent that yields still
                # drives its robot until it has stopped (close()): the earlier agent waits for it.
                stop = self._rival is not None and self.me.state == "claiming"
                doc = self.me.to_json()
            if stop:
                return
            try:
                self._pub.publish(m.json_string(doc))
            except Exception as exc:  # boundary: the transport is closing, or the network is gone
                log.warning("heartbeat not sent: %s", exc)
            self._closed.wait(self.period_s)

    def claim(self) -> None:
        """Heartbeats start; returns, now serving, once ``claim_s`` has passed with no agent of
        this robot heard whose claim came first, and no later one heard serving for ``claim_s``
        (it is stopping); raises :class:`AnotherAgentError` naming the earlier one heard."""
        self._thread.start()
        begun = time.monotonic()
        waited_for: set[str] = set()
        with self._cond:
            while self._rival is None:
                quiet = max(self._later_serving.values(), default=begun)
                ends = max(begun, quiet) + self.claim_s
                left = ends - time.monotonic()
                if left <= 0:
                    self.me = dataclasses.replace(self.me, state="serving")
                    return
                if self._later_serving.keys() - waited_for:
                    waited_for |= self._later_serving.keys()
                    log.warning("this agent serves once the later one has stopped")
                self._cond.wait(left)
        raise self.refusal()

    def refusal(self) -> AnotherAgentError:
        rival = self.rival
        assert rival is not None
        doing = "will not serve" if self.me.state == "claiming" else "stops serving"
        what = "serves this robot" if rival.state == "serving" else "claimed this robot first"
        return AnotherAgentError(
            f"another agent {what} on {self.where}: {describe(rival)}; this agent "
            f"(pid {self.me.pid}, log {self.me.log!r}) {doing}. Stop that agent first, or give "
            "this one a robot of its own (another domain_id, or other [topics] find and goal)"
        )

    def close(self) -> None:
        self._closed.set()
        if self._thread.is_alive():
            self._thread.join()
