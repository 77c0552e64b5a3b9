"""Real transports in separate processes on loopback; unique ports and DDS domains per test."""

from __future__ import annotations

import itertools
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

pytest.importorskip("zenoh")
pytest.importorskip("cyclonedds")

_domains = itertools.count(1 + os.getpid() % 150)

#: Seconds a test waits for a process it started to be ready (answer, listen, exit). Generous on
#: purpose: a fresh interpreter on a loaded machine takes seconds, and a wait that ends as soon
#: as the process is ready costs nothing when it is quick.
STARTUP_S = 120.0


def next_domain() -> int:
    """A DDS domain id no other test of this run uses (1..200)."""
    return next(_domains) % 200 + 1


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Net:
    """Command-line options that put every process of one test on the same private graph."""

    transport: str
    args: list[str]
    router: subprocess.Popen[bytes] | None = None


def objsearch(*args: str, log: Path) -> subprocess.Popen[bytes]:
    out = log.open("wb")
    return subprocess.Popen(
        [sys.executable, "-m", "objsearch.cli", *args], stdout=out, stderr=subprocess.STDOUT
    )


@pytest.fixture(params=["zenoh", "dds"])
def net(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Net]:
    if request.param == "zenoh":
        port = free_port()
        endpoint = f"tcp/127.0.0.1:{port}"
        router = objsearch("robot", "router", "--listen", endpoint, log=tmp_path / "router.txt")
        wait_listening(port, router)
        n = Net("zenoh", ["--transport", "zenoh", "--connect", endpoint], router)
    else:
        n = Net("dds", ["--transport", "dds", "--domain-id", str(next_domain())])
    yield n
    if n.router is not None:
        stop(n.router)


def wait_listening(port: int, proc: subprocess.Popen[bytes]) -> None:
    """Until something accepts connections on 127.0.0.1:``port`` (``proc`` is up), at most
    :data:`STARTUP_S`; fails at once if ``proc`` exits."""
    deadline = time.monotonic() + STARTUP_S
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1.0).close()
            return
        except OSError:
            assert proc.poll() is None, f"the process exited with {proc.returncode}"
            assert time.monotonic() < deadline, f"nothing listens on {port} after {STARTUP_S} s"
            time.sleep(0.05)


def stop(proc: subprocess.Popen[bytes]) -> int:
    """SIGTERM, then up to :data:`STARTUP_S` to finish (it closes its log and files), then
    SIGKILL."""
    if proc.poll() is None:
        proc.terminate()
        try:
            return proc.wait(STARTUP_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            return proc.wait(STARTUP_S)
    return proc.returncode
