"""The live view's WebSocket front door: both names of the Foxglove protocol are accepted (one of
them checked with Foxglove's own published client, ``@foxglove/ws-protocol`` under Node), and a
refused handshake is answered and logged with its reason."""

from __future__ import annotations

import base64
import contextlib
import json
import logging
import math
import os
import shutil
import socket
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from devtools.wsflood import closed_by_server
from objsearch.agent.catalogue import STORE
from objsearch.agent.session import load_context
from objsearch.events import Event, read_log
from objsearch.runtime import liveview as lv
from objsearch.runtime import messages as m
from objsearch.runtime.wsfront import (
    LEGACY_SUBPROTOCOL,
    SDK_SUBPROTOCOL,
    FrontLimits,
    Handshake,
    HandshakeRefused,
    choose_subprotocol,
)

GOLDEN = Path(__file__).resolve().parents[1] / "replay" / "golden" / "sim-wpl-updates"
CLIENT = Path(__file__).resolve().parent / "foxglove_client"


def request(*headers: str) -> Handshake:
    head = "\r\n".join(["GET / HTTP/1.1", "Host: x", "Upgrade: websocket", *headers])
    return Handshake.parse(head.encode())


@pytest.mark.parametrize(
    ("offered", "chosen"),
    [
        (LEGACY_SUBPROTOCOL, LEGACY_SUBPROTOCOL),
        (SDK_SUBPROTOCOL, SDK_SUBPROTOCOL),
        (f"{LEGACY_SUBPROTOCOL}, {SDK_SUBPROTOCOL}", SDK_SUBPROTOCOL),
        (f"other, {LEGACY_SUBPROTOCOL}", LEGACY_SUBPROTOCOL),
    ],
)
def test_choose_prefers_the_sdks_name(offered: str, chosen: str) -> None:
    assert choose_subprotocol(request(f"Sec-WebSocket-Protocol: {offered}")) == chosen


def test_choose_refuses_with_the_reason() -> None:
    with pytest.raises(HandshakeRefused, match=r"offered foxglove\.websocket\.v2; this server"):
        choose_subprotocol(request("Sec-WebSocket-Protocol: foxglove.websocket.v2"))
    with pytest.raises(HandshakeRefused, match="offered no subprotocol"):
        choose_subprotocol(request())
    plain = Handshake.parse(b"GET / HTTP/1.1\r\nHost: x")
    with pytest.raises(HandshakeRefused, match="not a WebSocket upgrade"):
        choose_subprotocol(plain)


@pytest.fixture(scope="module")
def events() -> list[Event]:
    return list(read_log(GOLDEN, store=STORE))


@pytest.fixture
def serving(events: list[Event]) -> Iterator[int]:
    """A live view that has drawn the log up to its first plan; yields its port."""
    pytest.importorskip("foxglove")
    from objsearch.runtime.livesinks import FoxgloveSink

    sink = FoxgloveSink(port=0)
    try:
        view = lv.LiveView(load_context("paper"), [sink])
        first_plan = next(i for i, e in enumerate(events) if e.type == "plan_computed")
        for e in events[: first_plan + 1]:
            view.apply(e)
        yield sink.port
    finally:
        sink.close()


@pytest.mark.parametrize(
    ("offered", "chosen"),
    [(LEGACY_SUBPROTOCOL, LEGACY_SUBPROTOCOL), (SDK_SUBPROTOCOL, SDK_SUBPROTOCOL)],
)
def test_both_names_get_the_stream(serving: int, offered: str, chosen: str) -> None:
    from .ws_client import FoxgloveClient

    client = FoxgloveClient("127.0.0.1", serving, subprotocols=offered)
    try:
        assert client.subprotocol == chosen
        assert client.json()["op"] == "serverInfo"
        advertised = client.json()
        assert advertised["op"] == "advertise"
        channel = next(c for c in advertised["channels"] if c["topic"] == lv.ROBOT)
        client.send_json(
            {"op": "subscribe", "subscriptions": [{"id": 3, "channelId": channel["id"]}]}
        )
        sub, _, payload = client.message_data()
        assert sub == 3
        assert m.decode(payload, m.POSE_STAMPED).header.frame_id == "map"
    finally:
        client.close()


def test_a_refused_handshake_is_answered_and_logged_with_its_reason(
    serving: int, caplog: pytest.LogCaptureFixture
) -> None:
    from .ws_client import FoxgloveClient
    from .ws_client import HandshakeRefused as Refused

    with caplog.at_level(logging.WARNING, logger="objsearch.liveview"):
        with pytest.raises(Refused) as refused:
            FoxgloveClient("127.0.0.1", serving, subprotocols="foxglove.websocket.v2")
        assert " 400 " in refused.value.status_line
        assert "the client offered foxglove.websocket.v2" in refused.value.body
        assert f"{SDK_SUBPROTOCOL} or {LEGACY_SUBPROTOCOL}" in refused.value.body
        with pytest.raises(Refused, match="offered no subprotocol"):
            FoxgloveClient("127.0.0.1", serving, subprotocols=None)
    logged = [r.getMessage() for r in caplog.records]
    assert any(
        "refused the WebSocket handshake of 127.0.0.1:" in line
        and "offered foxglove.websocket.v2" in line
        for line in logged
    ), logged


# -- Foxglove's published client --------------------------------------------------------------


def _installed(package: str) -> str | None:
    manifest = CLIENT / "node_modules" / package / "package.json"
    if not manifest.is_file():
        return None
    return str(json.loads(manifest.read_text())["version"])


@pytest.fixture(scope="module")
def foxglove_client() -> Path:
    """``connect.mjs`` with its pinned packages installed (``npm ci``, only when they are not)."""
    if shutil.which("node") is None:
        pytest.skip("node is not installed: Foxglove's client @foxglove/ws-protocol needs Node.js")
    pinned = json.loads((CLIENT / "package.json").read_text())["dependencies"]
    if any(_installed(name) != version for name, version in pinned.items()):
        npm = shutil.which("npm")
        assert npm is not None, "node is installed but npm is not: cannot install the client"
        done = subprocess.run(
            [npm, "ci", "--no-audit", "--no-fund", "--loglevel=error"],
            cwd=CLIENT,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert done.returncode == 0, f"npm ci failed in {CLIENT}:\n{done.stderr}"
    return CLIENT / "connect.mjs"


def test_foxglove_ws_protocol_client_gets_the_channels_and_messages(
    serving: int, foxglove_client: Path
) -> None:
    topics = [lv.MAP, lv.ROBOT, lv.SCENE_GRAPH]
    done = subprocess.run(
        ["node", str(foxglove_client), f"ws://127.0.0.1:{serving}", *topics],
        cwd=foxglove_client.parent,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    doc = json.loads(done.stdout.strip().splitlines()[-1])
    assert doc["subprotocol"] == LEGACY_SUBPROTOCOL  # what the published client offers
    assert doc["serverInfo"]["name"] == "objsearch"
    # none detected yet, no task ended (the per-task metrics)
    assert set(doc["channels"]) == set(lv.CHANNELS) - {lv.DETECTIONS, *lv.METRICS}
    assert doc["channels"][lv.MAP] == {
        "encoding": "cdr",
        "schemaName": lv.OCCUPANCY_GRID,
        "schemaEncoding": "ros2msg",
    }
    grid = m.decode(base64.b64decode(doc["messages"][lv.MAP][1]), lv.OCCUPANCY_GRID)
    expected = lv.occupancy_grid(load_context("paper"), 0)
    assert (grid.info.width, grid.info.height) == (expected.info.width, expected.info.height)
    assert (grid.data == expected.data).all()
    graph = json.loads(
        m.decode(base64.b64decode(doc["messages"][lv.SCENE_GRAPH][1]), m.STRING).data
    )
    assert graph["event"] == "plan_computed"


# -- limits: connections, handshakes, per-client queues ------------------------------------------

#: A complete, valid opening handshake, dripped byte by byte by the slow clients below.
HANDSHAKE = (
    "GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
    "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
    f"Sec-WebSocket-Protocol: {SDK_SUBPROTOCOL}\r\n\r\n"
).encode()
#: Generous: the loop turns at least once a second; this only bounds a test that would hang.
DEADLINE_S = 120.0


def os_threads() -> int:
    return len(os.listdir("/proc/self/task"))


def front_threads() -> list[str]:
    """The live view's Python threads (the SDK's own are Rust's, counted by :func:`os_threads`)."""
    return [t.name for t in threading.enumerate() if t.name.startswith("liveview")]


def until(check: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + DEADLINE_S
    while not check():
        assert time.monotonic() < deadline, f"not within {DEADLINE_S:g} s: {what}"
        time.sleep(0.05)


@pytest.fixture
def limited(events: list[Event]) -> Iterator[Callable[[FrontLimits], Any]]:
    """Starts live views with the given limits, each drawn up to the first plan; closes them."""
    pytest.importorskip("foxglove")
    from objsearch.runtime.livesinks import FoxgloveSink

    sinks: list[FoxgloveSink] = []

    def start(limits: FrontLimits) -> FoxgloveSink:
        sink = FoxgloveSink(port=0, limits=limits)
        sinks.append(sink)
        view = lv.LiveView(load_context("paper"), [sink])
        first_plan = next(i for i, e in enumerate(events) if e.type == "plan_computed")
        for e in events[: first_plan + 1]:
            view.apply(e)
        return sink

    yield start
    for sink in sinks:
        sink.close()


def subscribed(port: int, topic: str) -> Any:
    """A connected client subscribed (subscription id 1) to ``topic``."""
    from .ws_client import FoxgloveClient

    client = FoxgloveClient("127.0.0.1", port, timeout_s=DEADLINE_S)
    assert client.json()["op"] == "serverInfo"
    channels = client.json()["channels"]
    channel = next(c for c in channels if c["topic"] == topic)
    client.send_json({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel["id"]}]})
    return client


def test_limits_are_checked() -> None:
    for bad in (
        {"max_clients": 0},
        {"max_clients": 1025},
        {"client_queue_bytes": 1000},
        {"handshake_timeout_s": 0.0},
        {"handshake_timeout_s": math.nan},
    ):
        with pytest.raises(ValueError, match="the live view's"):
            FrontLimits(**bad)


def test_cli_checks_the_limits_and_needs_live_for_them(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from objsearch.cli import main

    log = str(tmp_path / "log")
    assert main(["agent", "run", "--log", log, "--live", "0", "--live-max-clients", "0"]) == 2
    assert "--live-max-clients: must be between 1 and 1024" in capsys.readouterr().err
    assert main(["agent", "run", "--log", log, "--live", "0", "--live-client-queue", "x"]) == 2
    assert "--live-client-queue: expected a whole number" in capsys.readouterr().err
    assert main(["agent", "run", "--log", log, "--live-max-clients", "4"]) == 2
    assert "they need --live [HOST:]PORT" in capsys.readouterr().err
    assert not (tmp_path / "log").exists()


def test_the_cli_options_reach_the_server() -> None:
    pytest.importorskip("foxglove")
    from objsearch.cli_runtime import live_sinks
    from objsearch.runtime.livesinks import FoxgloveSink

    (sink,) = live_sinks("0", None, max_clients=3, client_queue_mib=2)
    try:
        assert isinstance(sink, FoxgloveSink)
        assert sink.limits == FrontLimits(max_clients=3, client_queue_bytes=2 << 20)
    finally:
        sink.close()
    (sink,) = live_sinks("0", None)
    sink.close()
    assert isinstance(sink, FoxgloveSink) and sink.limits == FrontLimits()


def test_dripping_handshakes_stay_bounded_and_a_real_client_still_gets_in(
    limited: Callable[[FrontLimits], Any], caplog: pytest.LogCaptureFixture
) -> None:
    """Cap + 40 connections drip a valid handshake a byte at a time: the server never holds more
    than the cap, starts no thread for them, lets a well-behaved client in, and closes every
    dripper (the oldest to make room, the rest at the handshake timeout)."""
    cap, extra = 8, 40
    sink = limited(FrontLimits(max_clients=cap, handshake_timeout_s=2.0))
    threads = os_threads()
    assert front_threads() == ["liveview-front"]
    drippers: list[socket.socket] = []
    try:
        with caplog.at_level(logging.WARNING, logger="objsearch.liveview"):
            for _ in range(cap + extra):
                sock = socket.create_connection(("127.0.0.1", sink.port), timeout=DEADLINE_S)
                sock.sendall(HANDSHAKE[:1])
                drippers.append(sock)
            until(lambda: sink.stats().accepted == cap + extra, "every dripper accepted")
            held = sink.stats()
            assert held.connections == held.handshaking == cap
            assert held.evicted == extra
            for i in range(1, 6):  # still dripping: a byte each, far short of a handshake
                for sock in drippers:
                    with contextlib.suppress(OSError):
                        sock.send(HANDSHAKE[i : i + 1])
                assert sink.stats().connections <= cap
            assert front_threads() == ["liveview-front"]
            assert os_threads() <= threads + 2, (threads, os_threads())

            client = subscribed(sink.port, lv.ROBOT)
            try:
                sub, _, payload = client.message_data()
                assert sub == 1 and m.decode(payload, m.POSE_STAMPED).header.frame_id == "map"
            finally:
                client.close()
            until(lambda: all(closed_by_server(s) for s in drippers), "every dripper closed")
            until(lambda: sink.stats().connections == 0, "the server holds nothing")
        done = sink.stats()
        assert done.evicted + done.timed_out == cap + extra and done.timed_out >= cap - 1
        assert done.refused_full == 0 and done.dropped_slow == 0
        logged = " ".join(r.getMessage() for r in caplog.records)
        assert "to make room for" in logged and "handshake was not done after 2 s" in logged
        assert front_threads() == ["liveview-front"]
    finally:
        for sock in drippers:
            sock.close()


def test_over_the_cap_a_client_gets_503_until_a_place_frees(
    limited: Callable[[FrontLimits], Any],
) -> None:
    from .ws_client import FoxgloveClient
    from .ws_client import HandshakeRefused as Refused

    sink = limited(FrontLimits(max_clients=2))
    first = FoxgloveClient("127.0.0.1", sink.port, timeout_s=DEADLINE_S)
    second = FoxgloveClient("127.0.0.1", sink.port, timeout_s=DEADLINE_S)
    try:
        with pytest.raises(Refused) as refused:
            FoxgloveClient("127.0.0.1", sink.port, timeout_s=DEADLINE_S)
        assert " 503 " in refused.value.status_line
        assert "serves at most 2 clients at once" in refused.value.body
        assert sink.stats().refused_full == 1
        first.close()
        until(lambda: sink.stats().connections == 1, "the first client's place freed")
        third = FoxgloveClient("127.0.0.1", sink.port, timeout_s=DEADLINE_S)
        assert third.json()["op"] == "serverInfo"
        third.close()
    finally:
        first.close()
        second.close()


def test_a_client_that_never_reads_is_dropped_and_the_others_lose_nothing(
    limited: Callable[[FrontLimits], Any], caplog: pytest.LogCaptureFixture
) -> None:
    """One subscriber stops reading while 200 kB messages are published: once its queue passes
    the limit it is dropped; the queue never holds more than the limit and one read; the other
    subscriber gets every message."""
    queue = 256 * 1024
    sink = limited(FrontLimits(client_queue_bytes=queue))
    slow = subscribed(sink.port, lv.SCENE_GRAPH)
    slow.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    good = subscribed(sink.port, lv.SCENE_GRAPH)
    got: list[str] = []
    arrived = threading.Condition()

    def read() -> None:
        with contextlib.suppress(OSError, ConnectionError):
            while True:
                _, _, payload = good.message_data()
                text = m.decode(payload, m.STRING).data
                with arrived:
                    got.append(text[:16])
                    arrived.notify_all()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        with arrived:  # the latched scene graph, resent on subscribing
            assert arrived.wait_for(lambda: len(got) == 1, DEADLINE_S)
        got.clear()
        sent: list[str] = []
        with caplog.at_level(logging.WARNING, logger="objsearch.liveview"):
            for i in range(2000):
                tag = f"message {i:08d}"
                data = m.encode(m.string(tag + "x" * 200_000), m.STRING)
                sink.write(lv.LiveMessage(lv.SCENE_GRAPH, m.STRING, i, data))
                sent.append(tag[:16])
                with arrived:  # the good client keeps up: it is never the slow one
                    assert arrived.wait_for(lambda: len(got) == len(sent), DEADLINE_S)
                if sink.stats().dropped_slow:
                    break
        stats = sink.stats()
        print(f"dropped after {len(sent)} messages of 200 kB: {stats}")
        assert stats.dropped_slow == 1, stats
        assert queue < stats.peak_queue_bytes <= queue + 64 * 1024
        assert got == sent  # nothing lost, nothing out of order
        assert stats.connections == 1
        assert any(
            "bytes were waiting for it, over the limit of 262144" in r.getMessage()
            for r in caplog.records
        )
        deadline = time.monotonic() + DEADLINE_S
        with pytest.raises(ConnectionError):  # what reached it, then the end
            while time.monotonic() < deadline:
                slow.frame()
    finally:
        slow.close()
        good.sock.shutdown(socket.SHUT_RDWR)  # wakes the reader, blocked in recv
        good.close()
        reader.join(timeout=DEADLINE_S)
