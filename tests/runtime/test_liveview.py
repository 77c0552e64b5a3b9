"""The live view: a recorded log drawn into a ROS 2 MCAP (read back with rosbags), the Foxglove
WebSocket server (a real client over a socket), and the CLI's errors."""

from __future__ import annotations

import json
import math
import socket
import struct
from collections import defaultdict
from pathlib import Path
from typing import Any

import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader

from objsearch.agent.catalogue import STORE
from objsearch.agent.geometry import Point
from objsearch.agent.scene_graph import SceneGraphProjection
from objsearch.agent.session import load_context
from objsearch.agent.state import AgentState
from objsearch.cli import main
from objsearch.events import Event, fold, read_log
from objsearch.pipeline.bags.record import DEFAULT_START_NS
from objsearch.runtime import liveview as lv
from objsearch.runtime import messages as m
from objsearch.runtime.livesinks import FoxgloveSink, LiveViewError, McapSink, parse_address

GOLDEN = Path(__file__).resolve().parents[1] / "replay" / "golden" / "sim-wpl-updates"


@pytest.fixture(scope="module")
def events() -> list[Event]:
    return list(read_log(GOLDEN, store=STORE))


@pytest.fixture(scope="module")
def drawn(tmp_path_factory: pytest.TempPathFactory, events: list[Event]) -> Path:
    path = tmp_path_factory.mktemp("live") / "view.mcap"
    sink = McapSink(path)
    lv.render(events, [sink], clock_offset_ns=DEFAULT_START_NS)
    sink.close()
    return path


def read_all(path: Path) -> dict[str, list[tuple[int, Any]]]:
    out: dict[str, list[tuple[int, Any]]] = defaultdict(list)
    with AnyReader([path]) as reader:
        for conn, stamp, raw in reader.messages():
            out[conn.topic].append((stamp, reader.deserialize(raw, conn.msgtype)))
    return out


def by_task(events: list[Event]) -> dict[str, list[Event]]:
    tasks: dict[str, list[Event]] = defaultdict(list)
    for e in events:
        if e.task_id:
            tasks[e.task_id].append(e)
    return tasks


def test_mcap_is_a_ros2_bag_with_every_channel(drawn: Path, events: list[Event]) -> None:
    with drawn.open("rb") as fh:
        head = fh.read(64)
    assert head.startswith(b"\x89MCAP0\r\n")
    assert head[8] == 0x01  # the header record; its first field is the profile
    (n,) = struct.unpack_from("<I", head, 17)
    assert head[21 : 21 + n] == b"ros2"
    assert not list(drawn.parent.glob(".view.mcap.*")), "the temporary bag folder is left behind"
    with Reader(drawn) as reader:  # rosbags' ROS 2 reader on the bare file
        types = {c.topic: c.msgtype for c in reader.connections}
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert types == dict(lv.CHANNELS)
    kinds: defaultdict[str, int] = defaultdict(int)
    for e in events:
        kinds[e.type] += 1
    assert counts[lv.EVENTS] == len(events)
    assert counts[lv.PLAN] == kinds["plan_computed"] + kinds["task_started"]
    assert counts[lv.DETECTIONS] == kinds["detection"]
    assert counts[lv.ROUTE] == kinds["moved"] + kinds["task_started"]
    assert counts[lv.MAP] == counts[lv.STATICS] == 1


def test_route_length_is_the_task_path_length(drawn: Path, events: list[Event]) -> None:
    nav = load_context("paper").navmap
    topics = read_all(drawn)
    starts = [e for e in events if e.type == "task_started"]
    ends = [e for e in events if e.type == "task_ended"]
    routes = []
    for start, end in zip(starts, ends, strict=True):
        t0, t1 = DEFAULT_START_NS + start.time_ns, DEFAULT_START_NS + end.time_ns
        last = [msg for stamp, msg in topics[lv.ROUTE] if t0 <= stamp <= t1][-1]
        points = [Point(p.pose.position.x, p.pose.position.y) for p in last.poses]
        routes.append(points)
        assert nav.path_length(points) == pytest.approx(end.payload["path_length"], abs=1e-3)
        first = start.payload["pose"]
        assert math.dist(points[0], (first["x"], first["y"])) < 1e-6
    assert len(routes) == len(ends) == 8
    assert any(len(r) > 10 for r in routes)


def test_per_task_metrics_are_numbers_a_plot_panel_draws(drawn: Path, events: list[Event]) -> None:
    topics = read_all(drawn)
    ends = [e for e in events if e.type == "task_ended"]
    stamps = [DEFAULT_START_NS + e.time_ns for e in ends]
    assert [(t, msg.data) for t, msg in topics[lv.PATH_LENGTH]] == [
        (t, pytest.approx(e.payload["path_length"])) for t, e in zip(stamps, ends, strict=True)
    ]
    assert [msg.data for _, msg in topics[lv.SUCCESS]] == [
        float(e.payload["success"]) for e in ends
    ]
    # Rel(target, the static class it was found at), as the graph held it when the task began:
    # the fold of every event before the task's start.
    starts = {e.task_id: i for i, e in enumerate(events) if e.type == "task_started"}
    found_at: dict[str, str] = {}
    found = {e.task_id: e.payload["instance_id"] for e in events if e.type == "target_found"}
    for e in events:
        p = e.payload
        at = bool(p.get("support") and p["support"]["at"])
        if e.type == "detection" and at and p["instance_id"] == found.get(e.task_id):
            found_at.setdefault(str(e.task_id), p["support"]["static_class"])
    expected = []
    for e in ends:
        if str(e.task_id) in found_at:
            before = fold(events[: starts[e.task_id]], AgentState()).graph()
            target = events[starts[e.task_id]].payload["target"]
            expected.append(before.rel(target, found_at[str(e.task_id)]))
    rels = [msg.data for _, msg in topics[lv.TARGET_REL]]
    assert rels == pytest.approx(expected) and len(rels) >= 1
    assert all(0.0 <= r <= 1.0 for r in rels)


def test_plan_follows_the_plan_events_order(drawn: Path, events: list[Event]) -> None:
    topics = read_all(drawn)
    plans = [e for e in events if e.type == "plan_computed"]
    drawn_plans = [
        (stamp, msg) for stamp, msg in topics[lv.PLAN] if msg.poses
    ]  # an empty plan clears the view at each task start
    assert len(drawn_plans) == len(plans)
    for (stamp, msg), plan in zip(drawn_plans, plans, strict=True):
        assert stamp == DEFAULT_START_NS + plan.time_ns
        vp = {c["static_id"]: tuple(c["viewpoint"]) for c in plan.payload["candidates"]}
        expected: list[tuple[Any, ...]] = []
        for sid in plan.payload["order"]:
            if not expected or expected[-1] != vp[sid]:
                expected.append(vp[sid])
        assert [(p.pose.position.x, p.pose.position.y) for p in msg.poses] == expected


def test_scene_graph_channel_is_the_fold_of_the_log(drawn: Path, events: list[Event]) -> None:
    topics = read_all(drawn)
    last = json.loads(topics[lv.SCENE_GRAPH][-1][1].data)
    graph = fold(iter(events), SceneGraphProjection())
    assert last["seq"] == events[-1].seq
    assert last["tasks_folded"] == graph.tasks_folded
    assert last["relations"] == json.loads(json.dumps(graph.as_table()))
    task = last["task"]
    assert task["target"] == events[-1].payload["target"]
    rel = list(task["rel"].values())
    assert rel == sorted(rel, reverse=True)
    assert task["rel"] == graph.as_table()[task["target"]]


def test_map_frees_exactly_the_viewpoints(drawn: Path) -> None:
    ctx = load_context("paper")
    grid = read_all(drawn)[lv.MAP][0][1]
    info = grid.info
    res, ox, oy = info.resolution, info.origin.position.x, info.origin.position.y
    free = {
        (round(ox + (i % info.width + 0.5) * res, 4), round(oy + (i // info.width + 0.5) * res, 4))
        for i, v in enumerate(grid.data)
        if v == lv.FREE
    }
    assert free == {(p.x, p.y) for p in ctx.navmap.room_of}
    assert (grid.data == lv.OCCUPIED).sum() > 0
    statics = read_all(drawn)[lv.STATICS][0][1]
    assert len(statics.markers) == 2 * len(ctx.home.statics) + len(ctx.home.rooms)
    labels = {mk.text for mk in statics.markers if mk.type == lv.TEXT}
    assert {s.cls for s in ctx.home.statics.values()} | {r.name for r in ctx.home.rooms} == labels


def test_detections_use_the_robots_encoding(drawn: Path, events: list[Event]) -> None:
    dets = [e for e in events if e.type == "detection"]
    got = [msg for _, msg in read_all(drawn)[lv.DETECTIONS]]
    for msg, e in zip(got, dets, strict=True):
        (d,) = m.detections_of(msg)
        assert (d.object_class, d.instance_id) == (
            e.payload["object_class"],
            e.payload["instance_id"],
        )
        assert d.position == pytest.approx(tuple(e.payload["position"]))


def test_a_log_without_run_started_is_refused(tmp_path: Path, events: list[Event]) -> None:
    sink = McapSink(tmp_path / "x.mcap")
    with pytest.raises(Exception, match="before any run_started"):
        lv.render(events[1:], [sink])
    sink.abort()
    assert list(tmp_path.iterdir()) == []


# -- the command line --------------------------------------------------------------------------


def test_cli_writes_the_mcap_and_never_overwrites(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "v.mcap"
    assert main(["liveview", str(GOLDEN), "--mcap", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"{len(lv.CHANNELS)} channels" in text and lv.ROUTE in text
    size = out.stat().st_size
    assert main(["liveview", str(GOLDEN), "--mcap", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err
    assert out.stat().st_size == size


@pytest.mark.parametrize(
    ("target", "message"),
    [
        ("view.bag", "must end in .mcap"),
        ("afile/view.mcap", "is a file, not a folder"),
    ],
)
def test_cli_bad_output_path(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], target: str, message: str
) -> None:
    (tmp_path / "afile").write_text("a file, not a folder")
    assert main(["liveview", str(GOLDEN), "--mcap", str(tmp_path / target)]) == 2
    assert message in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]


def test_cli_corrupt_log_leaves_no_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "log"
    log.mkdir()
    (log / "meta.json").write_bytes((GOLDEN / "meta.json").read_bytes())
    lines = (GOLDEN / "events.log").read_bytes().splitlines(keepends=True)
    # A damaged record in the middle, followed by good ones: corruption, never skipped.
    (log / "events.log").write_bytes(b"".join([*lines[:50], b"garbage\n", *lines[50:]]))
    assert main(["liveview", str(log), "--mcap", str(tmp_path / "v.mcap")]) == 2
    assert "corrupt" in capsys.readouterr().err.lower()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log"]


# -- the WebSocket server ----------------------------------------------------------------------


def listening_addresses(port: int) -> set[str]:
    """Local addresses of the TCP sockets listening on ``port`` (from /proc/net/tcp{,6})."""
    found = set()
    for name in ("tcp", "tcp6"):
        path = Path("/proc/net") / name
        if not path.exists():
            continue
        for line in path.read_text().splitlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            addr, port_hex = local.rsplit(":", 1)
            if state == "0A" and int(port_hex, 16) == port:  # 0A: LISTEN
                found.add(addr)
    return found


def test_parse_address() -> None:
    assert parse_address("8765") == ("127.0.0.1", 8765)
    assert parse_address("0") == ("127.0.0.1", 0)
    assert parse_address("0.0.0.0:9000") == ("0.0.0.0", 9000)
    assert parse_address("[::1]:9000") == ("::1", 9000)
    for bad, why in [("abc", "not a number"), ("70000", "0–65535"), ("::1:9000", "IPv6")]:
        with pytest.raises(LiveViewError, match=why):
            parse_address(bad)


def test_server_binds_loopback_and_streams_the_channels(events: list[Event]) -> None:
    pytest.importorskip("foxglove")
    from .ws_client import FoxgloveClient

    sink = FoxgloveSink(port=0)
    try:
        assert sink.host == "127.0.0.1"
        assert listening_addresses(sink.port) == {"0100007F"}  # 127.0.0.1, nothing else
        view = lv.LiveView(load_context("paper"), [sink])
        first_task = next(i for i, e in enumerate(events) if e.type == "plan_computed")
        for e in events[: first_task + 1]:
            view.apply(e)
        client = FoxgloveClient("127.0.0.1", sink.port)
        try:
            assert client.subprotocol == "foxglove.sdk.v1"
            info = client.json()
            assert info["op"] == "serverInfo" and info["name"] == "objsearch"
            advertised: dict[str, dict[str, Any]] = {}
            # No detection yet, and no task has ended (the per-task metrics).
            while set(advertised) != set(lv.CHANNELS) - {lv.DETECTIONS, *lv.METRICS}:
                doc = client.json()
                assert doc["op"] == "advertise"
                advertised |= {c["topic"]: c for c in doc["channels"]}
            grid_channel = advertised[lv.MAP]
            assert grid_channel["encoding"] == "cdr"
            assert grid_channel["schemaEncoding"] == "ros2msg"
            assert grid_channel["schemaName"] == lv.OCCUPANCY_GRID
            assert "MSG: nav_msgs/MapMetaData" in grid_channel["schema"]
            # The map went out before this client came; subscribing gets it again.
            client.send_json(
                {"op": "subscribe", "subscriptions": [{"id": 7, "channelId": grid_channel["id"]}]}
            )
            sub, _, payload = client.message_data()
            assert sub == 7
            grid = m.decode(payload, lv.OCCUPANCY_GRID)
            expected = lv.occupancy_grid(load_context("paper"), 0)
            assert (grid.info.width, grid.info.height) == (
                expected.info.width,
                expected.info.height,
            )
            assert (grid.data == expected.data).all()
            # Live messages after subscribing arrive too.
            client.send_json(
                {
                    "op": "subscribe",
                    "subscriptions": [{"id": 8, "channelId": advertised[lv.ROBOT]["id"]}],
                }
            )
            seen = {client.message_data()[0]}  # the latched robot pose
            view.apply(events[first_task + 1])
            view.apply(events[first_task + 2])
            while 8 not in seen:
                seen.add(client.message_data()[0])
        finally:
            client.close()
    finally:
        sink.close()


def test_port_in_use_is_a_clear_error() -> None:
    pytest.importorskip("foxglove")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(LiveViewError, match=f"cannot serve the live view on 127.0.0.1:{port}"):
            FoxgloveSink(port=port)


# -- the agent over a real transport -----------------------------------------------------------


@pytest.mark.parametrize("net", ["zenoh"], indirect=True)
def test_agent_run_serves_and_records_the_live_view(net: Any, tmp_path: Path) -> None:
    """``agent run --live PORT --live-mcap FILE`` against the stand-in robot: a client sees the
    channels while it runs; after SIGTERM the MCAP holds the search the log holds."""
    pytest.importorskip("foxglove")
    from objsearch.cli import build_parser
    from objsearch.cli_runtime import runtime_config
    from objsearch.runtime.client import AgentClient

    from .runtime_fixtures import STARTUP_S, free_port, objsearch, stop
    from .searches import robot_config
    from .ws_client import FoxgloveClient

    port, mcap, log = free_port(), tmp_path / "live.mcap", tmp_path / "log"
    robot = objsearch("robot", "sim", *net.args, log=tmp_path / "robot.txt")
    agent = objsearch(
        "agent", "run", *net.args, *robot_config(tmp_path, ""), "--log", str(log),
        "--live", str(port), "--live-mcap", str(mcap), log=tmp_path / "agent.txt",
    )  # fmt: skip
    try:
        config = runtime_config(build_parser().parse_args(["agent", "find", "x", *net.args]))
        with AgentClient(config) as client:
            reset = client.reset_sim(1, "kitchen-1", timeout_s=STARTUP_S)
            assert reset["ok"]
            r = client.find(
                "Apple",
                start="kitchen-1",
                scene=1,
                timeout_s=STARTUP_S,
                not_before_ns=reset["stamp_ns"],
            )
            assert r["ok"] and r["success"], r
        ws = FoxgloveClient("127.0.0.1", port)
        try:
            assert ws.json()["op"] == "serverInfo"
            topics = {c["topic"] for c in ws.json()["channels"]}
            assert {lv.MAP, lv.ROUTE, lv.PLAN, lv.SCENE_GRAPH} <= topics
        finally:
            ws.close()
        assert listening_addresses(port) == {"0100007F"}
    finally:
        assert stop(agent) == 0, (tmp_path / "agent.txt").read_text()
        stop(robot)
    assert f"live view on ws://127.0.0.1:{port}" in (tmp_path / "agent.txt").read_text()
    logged = list(read_log(log, store=STORE))
    topics_read = read_all(mcap)
    assert len(topics_read[lv.EVENTS]) == len(logged)
    route = topics_read[lv.ROUTE][-1][1]
    points = [Point(p.pose.position.x, p.pose.position.y) for p in route.poses]
    assert load_context("paper").navmap.path_length(points) == pytest.approx(
        r["path_length"], abs=1e-3
    )


def test_detection_markers_hold_the_tasks_detections(drawn: Path, events: list[Event]) -> None:
    """Each message is the whole task so far (a late viewer needs only the last one); the found
    instance is green."""
    topics = read_all(drawn)
    for task_events in by_task(events).values():
        end = next(e for e in task_events if e.type == "task_ended")
        found = next((e for e in task_events if e.type == "target_found"), None)
        dets = [e.payload for e in task_events if e.type == "detection"]
        stamp = DEFAULT_START_NS + end.time_ns
        last = [msg for s, msg in topics[lv.DETECTION_MARKERS] if s <= stamp][-1]
        assert last.markers[0].action == lv.DELETEALL
        spheres = [mk for mk in last.markers if mk.type == lv.SPHERE and mk.action == lv.ADD]
        assert [(mk.pose.position.x, mk.pose.position.y) for mk in spheres] == [
            (d["position"][0], d["position"][1]) for d in dets
        ]
        green = [mk for mk in spheres if mk.color.g > 0.8 and mk.color.r < 0.2]
        if found is None:
            assert green == []
        else:
            assert {(mk.pose.position.x, mk.pose.position.y) for mk in green} == {
                (d["position"][0], d["position"][1])
                for d in dets
                if d["instance_id"] == found.payload["instance_id"]
            }
