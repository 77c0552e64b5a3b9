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
        time.sleep(0.3)
        n = Net("zenoh", ["--transport", "zenoh", "--connect", endpoint], router)
    else:
        n = Net("dds", ["--transport", "dds", "--domain-id", str(next(_domains) % 200 + 1)])
    yield n
    if n.router is not None:
        n.router.terminate()
        n.router.wait(10)


def stop(proc: subprocess.Popen[bytes]) -> int:
    if proc.poll() is None:
        proc.terminate()
        try:
            return proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            return proc.wait(10)
    return proc.returncode
