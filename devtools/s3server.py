"""A local S3 server for the fleet lake's tests and benchmarks: moto's, on a free loopback port.

:func:`s3_server` starts moto's server (the ``dev`` extra installs ``moto[server]``) through
:func:`main` here, waits until it answers (no fixed sleep), yields the standard ``AWS_*``
settings that point a client at it, and stops it. Nothing leaves the machine: the server listens
on 127.0.0.1 only.

Why not plain ``python -m moto.server``: moto (5.2.5) checks a conditional write
(``If-None-Match: *``, ``If-Match``) and then stores the object as two steps, in whichever of
its request threads runs them, with no lock between. Two writers that create the same key at
once can both pass the check, both get 200, and the later store replaces the earlier. A Delta
commit is exactly such a create (delta-rs puts ``_delta_log/<version>.json`` with
``If-None-Match: *``; the log store's contract is that of two writers of one version one
fails), so on plain moto two writers could both "commit" one version and the first one's
commit — acknowledged — was gone: the run the 8 × 50 writers' benchmark lost (issue 26,
``docs/analytics.md``). S3 itself makes a conditional write atomic; :func:`main` runs moto's
application with every conditional write holding one lock from its check to its store.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from typing import Any

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
        # by path: devtools/ is a folder of the checkout, not an installed package
        [sys.executable, __file__, "-H", "127.0.0.1", "-p", str(port)],
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


#: What a request that writes only if a condition holds carries (as WSGI names its headers).
_CONDITIONS = ("HTTP_IF_NONE_MATCH", "HTTP_IF_MATCH")


class AtomicConditionalWrites:
    """WSGI middleware: a conditional write (a ``PUT`` or ``POST`` — ``CompleteMultipartUpload``
    — with ``If-None-Match`` or ``If-Match``) runs whole, its answer built, under one lock, so
    its check and its store are one step as on S3: of two creates of one key, one gets 412.
    Other requests run as they come."""

    def __init__(self, app: Callable[..., Iterable[bytes]]) -> None:
        self.app = app
        self.lock = threading.Lock()

    def __call__(self, environ: dict[str, Any], start_response: Callable[..., Any]) -> Any:
        if environ.get("REQUEST_METHOD") in ("PUT", "POST") and any(
            h in environ for h in _CONDITIONS
        ):
            with self.lock:
                return list(self.app(environ, start_response))
        return self.app(environ, start_response)


def main(argv: list[str] | None = None) -> None:
    """``python devtools/s3server.py -H HOST -p PORT``: moto's S3 server (as
    ``python -m moto.server`` runs it) with :class:`AtomicConditionalWrites` in front."""
    import argparse

    from moto.moto_server.werkzeug_app import (
        DomainDispatcherApplication,
        MotoRequestHandler,
        create_backend_app,
    )
    from werkzeug.serving import run_simple

    parser = argparse.ArgumentParser(prog="python devtools/s3server.py")
    parser.add_argument("-H", "--host", default="127.0.0.1")
    parser.add_argument("-p", "--port", type=int, required=True)
    args = parser.parse_args(argv)
    os.environ.setdefault("MOTO_PORT", str(args.port))
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    app = DomainDispatcherApplication(create_backend_app)
    run_simple(
        args.host,
        args.port,
        AtomicConditionalWrites(app),
        threaded=True,
        request_handler=MotoRequestHandler,
    )


if __name__ == "__main__":
    main()
