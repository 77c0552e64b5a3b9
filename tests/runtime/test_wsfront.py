"""The live view's WebSocket front door: both names of the Foxglove protocol are accepted (one of
them checked with Foxglove's own published client, ``@foxglove/ws-protocol`` under Node), and a
refused handshake is answered and logged with its reason."""

from __future__ import annotations

import base64
import json
import logging
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from objsearch.agent.session import load_context
from objsearch.events import Event, read_log
from objsearch.runtime import liveview as lv
from objsearch.runtime import messages as m
from objsearch.runtime.wsfront import (
    LEGACY_SUBPROTOCOL,
    SDK_SUBPROTOCOL,
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
    return list(read_log(GOLDEN))


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
    assert set(doc["channels"]) == set(lv.CHANNELS) - {lv.DETECTIONS}  # none detected yet
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
