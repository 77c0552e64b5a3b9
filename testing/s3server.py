"""A local S3 server for the fleet lake's tests and benchmarks: moto's, on a free loopback port.

:func:`s3_server` starts ``python -m moto.server`` (the ``dev`` extra installs ``moto[server]``),
waits until it answers (no fixed sleep), yields the standard ``AWS_*`` settings that point a
client at it, and stops it. Nothing leaves the machine: the server listens on 127.0.0.1 only.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager

#: The servers running, by endpoint URL (for :func:`stalled`).
_SERVERS: dict[str, subprocess.Popen[bytes]] = {}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextmanager
def s3_server(start_timeout_s: float = 60.0) -> Iterator[dict[str, str]]:
    """moto's S3 server on a free loopback port; yields the ``AWS_*`` variables for it."""
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "moto.server", "-H", "127.0.0.1", "-p", str(port)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + start_timeout_s
    try:
        while True:  # until it answers: it starts as fast as the machine lets it
            try:
                urllib.request.urlopen(url, timeout=1).close()
                break
            except OSError:
                if proc.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"the S3 server on {url} did not start") from None
                time.sleep(0.05)
        _SERVERS[url] = proc
        yield {
            "AWS_ENDPOINT_URL": url,
            "AWS_ACCESS_KEY_ID": "testing",
            "AWS_SECRET_ACCESS_KEY": "testing",
            "AWS_REGION": "us-east-1",
        }
    finally:
        _SERVERS.pop(url, None)
        proc.terminate()
        proc.wait(timeout=30)


@contextmanager
def stalled(endpoint_url: str) -> Iterator[None]:
    """The server at ``endpoint_url`` (one :func:`s3_server` started) answers nothing inside the
    block: its process is stopped, and continued on leaving. Connections are still accepted
    (the kernel completes them), so a client sees a server that has gone quiet, as a loaded
    one does."""
    proc = _SERVERS[endpoint_url]
    os.kill(proc.pid, signal.SIGSTOP)
    try:
        yield
    finally:
        os.kill(proc.pid, signal.SIGCONT)
