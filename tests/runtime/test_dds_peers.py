"""The DDS transport among other participants: a peer that leaves costs nothing (no traceback,
no sample of the others lost), and a peer whose QoS cannot match is named in the log."""

from __future__ import annotations

import logging
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

pytest.importorskip("cyclonedds")

from objsearch.ros.qos import EVENTS, SENSOR_DATA, QoS
from objsearch.runtime import messages as m
from objsearch.runtime.backends import open_transport
from objsearch.runtime.transport import Backend, TransportConfig

from .runtime_fixtures import STARTUP_S, next_domain

#: A publisher in a process of its own: says hello until the test answers "go" on stdin, then
#: publishes ``count`` numbered messages a few ms apart and leaves (its participant deleted, as
#: when a node exits).
PEER = """
import sys, threading, time
from objsearch.ros.qos import QoS
from objsearch.runtime import messages as m
from objsearch.runtime.transport import Backend, TransportConfig
from objsearch.runtime.backends import open_transport
name, domain, count, qos = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), QoS.parse(sys.argv[4])
transport = open_transport(TransportConfig(backend=Backend.DDS, domain_id=domain))
pub = transport.publisher("/chatter", m.STRING, qos)
go = threading.Event()
threading.Thread(target=lambda: (sys.stdin.readline(), go.set()), daemon=True).start()
while not go.wait(0.05):
    pub.publish(m.encode(m.string(f"{name} hello"), m.STRING))
for i in range(count):
    pub.publish(m.encode(m.string(f"{name} {i}"), m.STRING))
    time.sleep(0.002)
transport.close()
"""


@contextmanager
def peer(name: str, domain: int, count: int, qos: QoS) -> Iterator[subprocess.Popen[str]]:
    qos_text = f"{qos.reliability.value},{qos.durability.value},{qos.depth}"
    proc = subprocess.Popen(
        [sys.executable, "-c", PEER, name, str(domain), str(count), qos_text],
        stdin=subprocess.PIPE,
        text=True,
    )
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()


class Heard:
    def __init__(self) -> None:
        self.lines: list[str] = []
        self._cond = threading.Condition()

    def __call__(self, data: bytes) -> None:
        with self._cond:
            self.lines.append(m.decode(data, m.STRING).data)
            self._cond.notify_all()

    def wait_for(self, line: str, timeout_s: float = STARTUP_S) -> None:
        with self._cond:
            assert self._cond.wait_for(lambda: line in self.lines, timeout_s), (
                f"never heard {line!r}"
            )


def test_a_peer_leaving_loses_nothing_and_raises_nothing(
    capfd: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Cyclone reports an exception raised in a listener through ``sys.unraisablehook`` (the
    listener is a C callback), so that is where a traceback would go: it is collected here."""
    unraisable: list[str] = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: unraisable.append(repr(u.exc_value)))
    domain = next_domain()
    agent = open_transport(TransportConfig(backend=Backend.DDS, domain_id=domain))
    heard = Heard()
    try:
        agent.subscribe("/chatter", m.STRING, EVENTS, heard)
        with (
            peer("leaver", domain, 200, EVENTS) as leaver,
            peer("stayer", domain, 1500, EVENTS) as stayer,
        ):
            heard.wait_for("leaver hello")
            heard.wait_for("stayer hello")
            for proc in (leaver, stayer):
                assert proc.stdin is not None
                proc.stdin.write("go\n")
                proc.stdin.flush()
            assert leaver.wait(STARTUP_S) == 0  # left while the stayer publishes
            heard.wait_for("leaver 199")
            heard.wait_for("stayer 1499")
            assert stayer.wait(STARTUP_S) == 0
    finally:
        agent.close()
    numbered = [line for line in heard.lines if not line.endswith("hello")]
    assert [x for x in numbered if x.startswith("stayer")] == [f"stayer {i}" for i in range(1500)]
    assert [x for x in numbered if x.startswith("leaver")] == [f"leaver {i}" for i in range(200)]
    assert unraisable == []
    err = capfd.readouterr().err
    assert "Traceback" not in err and "InvalidSample" not in err, err


def test_a_qos_mismatch_is_named_in_the_log(caplog: pytest.LogCaptureFixture) -> None:
    """A best-effort odometry publisher (a sensor-data profile) never meets the agent's reliable
    reader; the agent says so within seconds, naming the topic and the policy."""
    domain = next_domain()
    with caplog.at_level(logging.INFO, "objsearch.runtime"):
        agent = open_transport(TransportConfig(backend=Backend.DDS, domain_id=domain))
    assert f"joined DDS domain {domain} (ROS_DOMAIN_ID) on lo (127.0.0.1)" in caplog.text
    try:
        with caplog.at_level(logging.WARNING, "objsearch.runtime"):
            agent.subscribe("/chatter", m.STRING, EVENTS, lambda data: None)
            with peer("sensor", domain, 0, SENSOR_DATA):
                deadline = time.monotonic() + STARTUP_S
                while "QoS mismatch" not in caplog.text:
                    assert time.monotonic() < deadline, "no QoS mismatch reported"
                    time.sleep(0.05)
    finally:
        agent.close()
    assert "QoS mismatch on /chatter" in caplog.text
    assert "reliability differs" in caplog.text
    assert "reader (reliable, volatile, depth 1000)" in caplog.text
