"""``objsearch agent run|find|where`` and ``objsearch robot sim|router``: the on-robot runtime."""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from objsearch import cli_types as t

if TYPE_CHECKING:
    from collections.abc import Callable

    from objsearch.runtime.client import AgentClient
    from objsearch.runtime.config import RuntimeConfig
    from objsearch.runtime.liveview import LiveSink


def _transport_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--config",
        type=t.existing_file,
        help="robot.toml (transport, domain, endpoints, topics, QoS)",
    )
    p.add_argument(
        "--transport",
        choices=["zenoh", "dds", "ros2"],
        help="zenoh or dds (no ROS 2 needed), or ros2 (an rclpy node) (zenoh)",
    )
    p.add_argument("--domain-id", type=t.int_range(0, 232), help="ROS_DOMAIN_ID, 0-232 (0)")
    p.add_argument(
        "--connect",
        action="append",
        type=t.zenoh_endpoint,
        help="zenoh endpoint to connect to (tcp/127.0.0.1:7447)",
    )
    p.add_argument(
        "--listen",
        action="append",
        type=t.zenoh_endpoint,
        help="zenoh endpoint to listen on (PROTO/HOST:PORT)",
    )
    p.add_argument("--mode", choices=["peer", "client"], help="zenoh session mode (peer)")
    p.add_argument(
        "--peer", action="append", type=t.host, help="DDS unicast discovery peer (127.0.0.1)"
    )
    p.add_argument("--interface", type=t.text, help="DDS network interface (lo)")
    p.add_argument("--home", type=t.text, help="home in data/homes (paper)")


def runtime_config(args: argparse.Namespace) -> RuntimeConfig:
    from objsearch.runtime.config import RuntimeConfig
    from objsearch.runtime.transport import Backend

    config = RuntimeConfig.load(Path(args.config)) if args.config else RuntimeConfig()
    t = config.transport
    changes: dict[str, Any] = {}
    if args.transport:
        changes["backend"] = Backend(args.transport)
    if args.domain_id is not None:
        changes["domain_id"] = args.domain_id
    if args.connect:
        changes["connect"] = tuple(args.connect)
    if args.listen:
        changes["listen"] = tuple(args.listen)
    if args.mode:
        changes["mode"] = args.mode
    if args.peer:
        changes["peers"] = tuple(args.peer)
    if args.interface:
        changes["interface"] = args.interface
    config = replace(config, transport=replace(t, **changes))
    if args.home:
        config = replace(config, home=args.home)
    return config


def _ros_environment(config: RuntimeConfig) -> None:
    """Over ``--transport ros2`` the command starts again once with the environment rclpy needs
    (runtime/ros2_env.py): only the processes that use rclpy pay for it."""
    from objsearch.runtime.transport import Backend

    if config.transport.backend is Backend.ROS2:
        from objsearch.runtime import ros2_env

        ros2_env.reexec()


def _node_named(config: RuntimeConfig, name: str) -> RuntimeConfig:
    """Every transport puts its node on ROS 2's graph (rclpy; ros_discovery_info over dds;
    liveliness tokens over zenoh), and two of one name confuse the graph tools: the stand-in
    and the clients take their own unless robot.toml names the node."""
    from objsearch.runtime.transport import TransportConfig

    t = config.transport
    if t.node != TransportConfig().node:
        return config
    return replace(config, transport=replace(t, node=name))


def _stop_on_signals(stop: Any) -> None:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop())


def _logging() -> None:
    logging.getLogger("objsearch").setLevel(logging.INFO)


def live_sinks(
    live: str | None,
    live_mcap: str | None,
    *,
    compress: bool = True,
    max_clients: int | None = None,
    client_queue_mib: int | None = None,
) -> list[LiveSink]:
    """The live view's sinks from ``--live [HOST:]PORT`` and ``--live-mcap FILE`` (none: off);
    ``--live-max-clients`` and ``--live-client-queue`` bound the server's clients.

    If the second cannot start, the first is closed again before the error is raised."""
    from objsearch.agent.errors import ObjsearchError
    from objsearch.runtime.livesinks import FoxgloveSink, McapSink, parse_address
    from objsearch.runtime.wsfront import FrontLimits

    if live is None and (max_clients is not None or client_queue_mib is not None):
        raise ObjsearchError(
            "--live-max-clients and --live-client-queue bound the live view's server: "
            "they need --live [HOST:]PORT"
        )
    defaults = FrontLimits()
    limits = FrontLimits(
        max_clients=defaults.max_clients if max_clients is None else max_clients,
        client_queue_bytes=(
            defaults.client_queue_bytes if client_queue_mib is None else client_queue_mib << 20
        ),
    )
    sinks: list[LiveSink] = []
    try:
        if live is not None:
            host, port = parse_address(live)
            server = FoxgloveSink(host, port, limits=limits)
            sinks.append(server)
            print(
                f"objsearch agent: live view on ws://{_host_for_url(server.host)}:{server.port} "
                "(Foxglove: Open connection → Foxglove WebSocket)",
                file=sys.stderr,
                flush=True,
            )
        if live_mcap is not None:
            sinks.append(McapSink(Path(live_mcap), compress=compress))
    except BaseException:
        for sink in sinks:
            sink.close()
        raise
    return sinks


def _host_for_url(host: str) -> str:
    return f"[{host}]" if ":" in host else host


def cmd_agent_run(args: argparse.Namespace) -> int:
    from objsearch.agent.scene_graph import UpdateMode
    from objsearch.runtime.agent_node import AgentNode

    # Ctrl-C stops the agent at every stage, also while it joins the graph and restores its
    # state (a long log takes a while): until the node can stop itself, SIGINT raises
    # KeyboardInterrupt (exit 130; what is open is closed on the way out; the log is append-only
    # and the snapshot a cache, so nothing is lost), even where the agent was started with
    # SIGINT ignored (a shell script's background job), as the handlers installed below do.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    _logging()
    config = runtime_config(args)  # bad options fail before a port is taken or a file made
    _ros_environment(config)
    sinks = live_sinks(
        args.live,
        args.live_mcap,
        compress=not args.no_compress,
        max_clients=args.live_max_clients,
        client_queue_mib=args.live_client_queue,
    )
    node = AgentNode(
        config,
        Path(args.log),
        strategy=args.strategy or config.strategy,
        alpha=args.alpha,
        seed=args.seed,
        update_mode=UpdateMode(args.update_mode),
        live=sinks,
        live_topics=args.live_topics,
        perception=t.perception_params(args),
    )
    _stop_on_signals(node.stop)
    print(f"objsearch agent: serving searches, log {args.log}", file=sys.stderr, flush=True)
    return node.run()


def cmd_liveview(args: argparse.Namespace) -> int:
    from objsearch.pipeline.bags.record import DEFAULT_START_NS
    from objsearch.replay.source import open_events
    from objsearch.runtime.livesinks import McapSink
    from objsearch.runtime.liveview import CHANNELS, render

    events, name = open_events(args.log, run=args.run, robot=args.robot)
    started = time.perf_counter()
    sink = McapSink(Path(args.mcap), compress=not args.no_compress)
    try:
        render(
            t.progress(events, "liveview", " events", enabled=not args.no_progress),
            [sink],
            clock_offset_ns=DEFAULT_START_NS if args.sim_clock else 0,
        )
    except BaseException:
        sink.abort()  # no half-drawn file at --mcap
        raise
    sink.close()
    seconds = time.perf_counter() - started
    total = sum(sink.counts.values())
    if args.format == "json":
        doc = {
            "mcap": args.mcap,
            "source": name,
            "bytes": Path(args.mcap).stat().st_size,
            "compressed": not args.no_compress,
            "messages": total,
            "seconds": round(seconds, 3),
            "channels": {
                topic: {"type": CHANNELS[topic], "messages": sink.counts[topic]}
                for topic in CHANNELS
                if topic in sink.counts
            },
        }
        print(json.dumps(doc, indent=2))
        return 0
    print(
        f"{args.mcap}: {total} messages on {len(sink.counts)} channels from {name} "
        f"in {seconds:.2f} s ({Path(args.mcap).stat().st_size / 1e6:.1f} MB)"
    )
    for topic in CHANNELS:
        if topic in sink.counts:
            print(f"  {topic:36} {CHANNELS[topic]:36} {sink.counts[topic]:>7}")
    return 0


#: Seconds ``agent find`` and ``agent where`` wait before it says that nobody can hear it.
NO_ANSWER_HINT_S = 3.0


def nobody_hears(config: RuntimeConfig, transport: Any, timeout_s: float) -> str | None:
    """Why a request cannot be answered and what to start, if the transport can tell: a zenoh
    session connected to no router and no peer. None when someone may be listening (an agent
    answers a find only when its search ends, so silence alone says nothing)."""
    t = config.transport
    reachable = getattr(transport, "reachable", None)
    if t.backend.value != "zenoh" or reachable is None or reachable() > 0:
        return None
    return (
        f"nobody answers: no zenoh router or peer is reachable at "
        f"{', '.join(t.connect) or '(no --connect endpoint)'}. Start a router with "
        "`objsearch robot router` (rmw_zenoh's robots run `ros2 run rmw_zenoh_cpp rmw_zenohd`), "
        "then the agent with `objsearch agent run --log LOG`; still waiting up to "
        f"{timeout_s:g} s (--timeout)"
    )


def _ask(
    args: argparse.Namespace, command: str, call: Callable[[AgentClient], dict[str, Any]]
) -> dict[str, Any]:
    """``call(client)``'s answer; after :data:`NO_ANSWER_HINT_S` without one, says on stderr
    why nobody may be answering (:func:`nobody_hears`), and keeps waiting up to --timeout."""
    import threading

    from objsearch.runtime.client import AgentClient

    config = _node_named(runtime_config(args), f"objsearch_client_{os.getpid()}")
    _ros_environment(config)
    with AgentClient(config) as client:

        def hint_if_alone() -> None:
            why = nobody_hears(config, client.node.transport, args.timeout)
            if why is not None:
                print(f"objsearch {command}: {why}", file=sys.stderr, flush=True)

        hint = threading.Timer(NO_ANSWER_HINT_S, hint_if_alone)
        hint.daemon = True
        hint.start()
        try:
            result = call(client)
        finally:
            hint.cancel()
    return result


def cmd_agent_find(args: argparse.Namespace) -> int:
    result = _ask(
        args,
        "agent find",
        lambda client: client.find(
            args.target, start=args.start, scene=args.scene, timeout_s=args.timeout
        ),
    )
    if args.format == "json":
        print(json.dumps(result, indent=2, sort_keys=True))
    elif not result.get("ok"):
        print(f"search failed: {result.get('error')}")
    else:
        verdict = "found" if result["success"] else "NOT found"
        print(
            f"{verdict}: {result['target']} ({result['task_id']}), "
            f"path length {result['path_length']:.2f} m"
            + (f", {result['found']}" if result.get("found") else "")
        )
    if not result.get("ok"):
        return 2
    return 0 if result["success"] else 1


def cmd_agent_where(args: argparse.Namespace) -> int:
    from objsearch.agent.where import render

    result = _ask(
        args, "agent where", lambda client: client.where(args.target, timeout_s=args.timeout)
    )
    if args.format == "json":
        print(json.dumps(result, indent=2, sort_keys=True))
    elif not result.get("ok"):
        print(f"where failed: {result.get('error')}")
    else:
        print(render(result["answer"]))
    return 0 if result.get("ok") else 2


def cmd_agent_replay(args: argparse.Namespace) -> int:
    """A recorded robot session (a bag of the agent's events, the robot's odometry and its
    detector's views) replayed to a fresh agent: the same decisions, or where they part."""
    import tempfile

    from objsearch.agent.errors import ObjsearchError
    from objsearch.pipeline.bags.views import (
        ReplayDiverged,
        decisions,
        first_difference,
        read_recording,
        replay_recording,
    )
    from objsearch.runtime.config import RuntimeConfig

    config = RuntimeConfig.load(Path(args.config)) if args.config else RuntimeConfig()
    if args.home:
        config = replace(config, home=args.home)
    if config.pose.source != "odometry":
        raise ObjsearchError(
            "agent replay reads the robot's poses from odometry; [pose] source = "
            f"{config.pose.source!r} is not replayed"
        )
    recording = read_recording(Path(args.bag), _bag_topics(config), input=config.detections.input)
    recorded = decisions(recording.agent)
    doc: dict[str, Any] = {
        "bag": args.bag,
        "tasks": sum(e.type == "task_started" for e in recording.agent),
        "decisions": len(recorded),
        "same": False,
        "first_difference": None,
        "diverged": None,
        "unread_views": recording.rejected,
    }
    with tempfile.TemporaryDirectory(prefix="objsearch-replay-") as tmp:
        log_dir = Path(args.log) if args.log else Path(tmp) / "log"
        try:
            replay = replay_recording(
                recording,
                config.home,
                log_dir,
                progress=lambda tasks: t.progress(
                    tasks, "agent replay", " tasks", enabled=not args.no_progress
                ),
            )
        except ReplayDiverged as exc:
            doc["diverged"] = str(exc)
        else:
            replayed = decisions(replay.replayed)
            i = first_difference(recorded, replayed)
            doc["same"] = i is None
            if i is not None:
                doc["first_difference"] = {
                    "index": i,
                    "recorded": _decision(recorded, i),
                    "replayed": _decision(replayed, i),
                }
    if args.format == "json":
        print(json.dumps(doc, indent=2, default=str))
    else:
        for why, n in recording.rejected.items():
            print(f"note: {n} view(s) could not be read: {why}")
        print(f"{doc['tasks']} task(s), {doc['decisions']} decision events recorded in {args.bag}")
        if doc["same"]:
            print("replayed: every decision as recorded")
        elif doc["diverged"]:
            print(f"replayed: DIFFERENT, the replay left the recording: {doc['diverged']}")
        else:
            d = doc["first_difference"]
            print(f"replayed: DIFFERENT from decision event {d['index']}")
            print(f"    recorded {d['recorded']}")
            print(f"    replayed {d['replayed']}")
    return 0 if doc["same"] else 1


def _bag_topics(config: RuntimeConfig) -> Any:
    """The bag's topic map: the topics and frames robot.toml gave the live agent."""
    from objsearch.ros.topics import Frames, Role, TopicMap

    tp = config.topics
    return TopicMap(
        topics={
            tp.odometry: Role.ODOMETRY,
            tp.tf: Role.TF,
            tp.tf_static: Role.TF_STATIC,
            tp.camera_info: Role.CAMERA_INFO,
            tp.depth: Role.DEPTH,
            tp.detections: Role.DETECTIONS,
            tp.events: Role.EVENTS,
        },
        frames=Frames(map=config.pose.map_frame, base=config.pose.base_frame),
    )


def _decision(events: list[Any], i: int) -> Any:
    if i >= len(events):
        return None
    kind, version, task, payload = events[i]
    return {"type": kind, "version": version, "task_id": task, "payload": payload}


def cmd_robot_sim(args: argparse.Namespace) -> int:
    from objsearch.agent.detector_model import PerceptionModel
    from objsearch.runtime.standin import Faults, StandInRobot

    _logging()
    config = _node_named(runtime_config(args), "objsearch_robot")
    _ros_environment(config)
    robot = StandInRobot(
        config,
        schedule=args.schedule,
        scene=args.scene,
        start=args.start,
        faults=Faults(
            args.drop_every,
            args.exit_after,
            args.malformed_after,
            args.reject_after,
            args.abort_after,
            args.mute_after,
            args.stall_after,
        ),
        perception=PerceptionModel.from_params(t.perception_params(args)),
        seed=args.seed,
    )
    _stop_on_signals(robot.stop)
    print("objsearch robot: stand-in up", file=sys.stderr, flush=True)
    return robot.run()


def cmd_robot_router(args: argparse.Namespace) -> int:
    """A zenoh router, for a machine without ``ros2 run rmw_zenoh_cpp rmw_zenohd``."""
    from objsearch.runtime.transport import Backend, TransportConfig
    from objsearch.runtime.zenoh_transport import ZenohTransport

    listen = tuple(args.listen or ["tcp/127.0.0.1:7447"])
    router = ZenohTransport(
        TransportConfig(Backend.ZENOH, mode="router", connect=(), listen=listen, node="router")
    )
    stopped: list[bool] = []
    _stop_on_signals(lambda: stopped.append(True))
    print(f"objsearch router: listening on {', '.join(listen)}", file=sys.stderr, flush=True)
    while not stopped:
        time.sleep(0.2)
    router.close()
    return 0


def _live_client_options(p: argparse.ArgumentParser) -> None:
    """Added when ``agent run`` is first used: the limits come from the WebSocket front."""
    from objsearch.runtime.wsfront import (
        DEFAULT_CLIENT_QUEUE_BYTES,
        DEFAULT_MAX_CLIENTS,
        MAX_CLIENTS_LIMIT,
    )

    p.add_argument(
        "--live-max-clients",
        metavar="N",
        type=t.int_range(1, MAX_CLIENTS_LIMIT),
        help=f"serve at most N live-view clients at once, 1-{MAX_CLIENTS_LIMIT} "
        f"({DEFAULT_MAX_CLIENTS}); more get HTTP 503",
    )
    p.add_argument(
        "--live-client-queue",
        metavar="MIB",
        type=t.int_range(1, 1024),
        help="drop a live-view client once more than MIB mebibytes wait for it, 1-1024 "
        f"({DEFAULT_CLIENT_QUEUE_BYTES >> 20})",
    )


def _strategy_option(p: argparse.ArgumentParser) -> None:
    """Added when ``agent run`` is first used: the strategies import the agent."""
    from objsearch.agent.strategies import DEFAULT_STRATEGY

    p.add_argument(
        "--strategy",
        type=t.strategy,
        help="search strategy, NAME or NAME+cover (objsearch bench compares them; default: "
        f"robot.toml's strategy, else {DEFAULT_STRATEGY})",
    )


def _add_run(agent_sub: Any) -> None:
    run = agent_sub.add_parser("run", help="serve search requests, driving the robot")
    _transport_options(run)
    run.add_argument("--log", required=True, type=t.dir_path, help="the agent's event log folder")
    run.defer(_strategy_option)
    run.add_argument("--alpha", type=t.ALPHA, default=10.0, help="alpha of Eq. 3, 0-1000 (10)")
    run.add_argument("--seed", type=t.SEED, default=0, help="seed (0)")
    run.add_argument("--update-mode", default="all", choices=["none", "targets", "all"])
    run.add_argument(
        "--live",
        metavar="[HOST:]PORT",
        type=t.optional_host_port,
        help="serve the live view to Foxglove on this WebSocket port (host 127.0.0.1 unless "
        "given; 0 picks a free port); off by default",
    )
    run.add_argument(
        "--live-topics",
        action="store_true",
        help="also publish the live view's channels as topics of the robot's graph (RViz2)",
    )
    run.add_argument(
        "--live-mcap",
        metavar="FILE",
        type=t.new_path,
        help="also write the live view's channels to FILE.mcap",
    )
    run.defer(_live_client_options)
    run.add_argument(
        "--no-compress",
        action="store_true",
        help="write --live-mcap's chunks uncompressed (by default zstd, as ros2 bag record)",
    )
    t.perception_option(run)
    run.set_defaults(func=cmd_agent_run)


def _add_find(agent_sub: Any) -> None:
    find = agent_sub.add_parser("find", help="ask the running agent to find an object")
    find.add_argument("target", metavar="TARGET", type=t.text, help="object class, e.g. Apple")
    _transport_options(find)
    find.add_argument("--start", type=t.text, help="a label for where the robot starts (recorded)")
    find.add_argument("--scene", type=t.SCENE, help="the schedule scene (recorded; the stand-in's)")
    find.add_argument(
        "--timeout",
        type=t.float_range(0.0, 86_400.0, lo_open=True),
        default=600.0,
        help="seconds to wait, up to a day (600)",
    )
    t.format_option(find, "print JSON")
    find.set_defaults(func=cmd_agent_find)


def _add_where(agent_sub: Any) -> None:
    where = agent_sub.add_parser(
        "where",
        help="ask the running agent where an object was last seen, where it usually is, how sure",
        description="Answered from the agent's live memory (the projection `objsearch where "
        "--log` folds), even while it searches.",
    )
    where.add_argument("target", metavar="TARGET", type=t.text, help="object class, e.g. Cup")
    _transport_options(where)
    where.add_argument(
        "--timeout",
        type=t.float_range(0.0, 86_400.0, lo_open=True),
        default=30.0,
        help="seconds to wait, up to a day (30)",
    )
    t.format_option(where, "print the result as JSON")
    where.set_defaults(func=cmd_agent_where)


def _add_replay(agent_sub: Any) -> None:
    replay = agent_sub.add_parser(
        "replay",
        help="replay a recorded robot session (a bag) to a fresh agent: the same decisions?",
        description="Reads the agent's events, the robot's odometry and its detector's views "
        "from BAG (the topics and [detections] input of --config's robot.toml), searches again "
        "for each recorded task with the recorded run's settings, each robot command answered "
        "by the recorded pose and view the live agent would take, and compares every decision. "
        "Exit status 0 when all are the same, 1 when any differs.",
    )
    replay.add_argument(
        "bag", metavar="BAG", type=t.existing_path, help="the session's bag (ROS 2 or ROS 1)"
    )
    replay.add_argument(
        "--config",
        type=t.existing_file,
        help="the robot.toml the agent ran with (topics, frames, [detections] input, home)",
    )
    replay.add_argument("--home", type=t.text, help="home in data/homes (robot.toml's, else paper)")
    replay.add_argument(
        "--log", type=t.dir_path, help="keep the replayed agent's event log here (a new folder)"
    )
    t.format_option(replay, "print the comparison as JSON")
    t.progress_option(replay)
    replay.set_defaults(func=cmd_agent_replay)


def _add_sim(robot_sub: Any) -> None:
    sim = robot_sub.add_parser("sim", help="the simulator behind a real robot's ROS 2 topics")
    _transport_options(sim)
    fault_count = t.int_range(0, 1_000_000)
    sim.add_argument("--schedule", default="table2", type=t.text, help="schedule (table2)")
    sim.add_argument(
        "--scene", type=t.SCENE, help="place objects as in this scene (default: Table I)"
    )
    sim.add_argument("--start", type=t.text, help="start point (the home's first)")
    sim.add_argument(
        "--drop-every", type=fault_count, default=0, help="fault: drop every n-th message"
    )
    sim.add_argument(
        "--exit-after", type=fault_count, default=0, help="fault: vanish after n goals"
    )
    sim.add_argument(
        "--malformed-after", type=fault_count, default=0, help="fault: garbage after n goals"
    )
    for fault, what in (
        ("reject", "reject the n-th navigate_to_pose goal"),
        ("abort", "abort the n-th navigate_to_pose goal"),
        ("mute", "leave send_goal unanswered from the n-th goal on"),
        ("stall", "accept the n-th goal and never finish it"),
    ):
        sim.add_argument(f"--{fault}-after", type=fault_count, default=0, help=f"fault: {what}")
    sim.add_argument("--seed", type=t.SEED, default=0, help="seed of the detector model (0)")
    t.perception_option(sim)
    sim.set_defaults(func=cmd_robot_sim)


def _add_view(sub: Any) -> None:
    view = sub.add_parser(
        "liveview",
        help="draw a recorded log's live-view channels into an MCAP file for Foxglove",
        description="Replays the log through the live view the agent serves with --live "
        "(map, static objects, plan, route, robot, detections, scene graph, events) and writes "
        "the channels to a ROS 2 MCAP file (rosbag2, CDR) that Foxglove and rosbags read.",
    )
    view.add_argument(
        "log",
        metavar="LOG|LAKE",
        type=t.log_or_lake,
        help="event log folder, or a lake (with --run): a folder or s3://bucket/prefix",
    )
    view.add_argument(
        "--mcap",
        required=True,
        metavar="FILE",
        type=t.new_path,
        help="the .mcap file to write (never overwritten)",
    )
    view.add_argument("--run", type=t.text, help="the lake run to draw")
    view.add_argument("--robot", type=t.text, help="the robot whose run it is, if run names repeat")
    view.add_argument(
        "--no-compress",
        action="store_true",
        help="write the MCAP's chunks uncompressed (by default zstd with CRCs, as ros2 bag "
        "record; about 15 times larger)",
    )
    t.format_option(view, "print what was written as JSON")
    t.progress_option(view)
    view.add_argument(
        "--robot-clock",
        dest="sim_clock",
        action="store_false",
        help="stamp with the log's clock as is (a robot's log); by default a simulated log's "
        "clock starts at 2026-01-01, as objsearch record's bags do",
    )
    view.set_defaults(func=cmd_liveview)


def _add_router(robot_sub: Any) -> None:
    router = robot_sub.add_parser("router", help="a zenoh router (rmw_zenohd's role)")
    router.add_argument(
        "--listen",
        action="append",
        type=t.zenoh_endpoint,
        help="endpoint (tcp/127.0.0.1:7447)",
    )
    router.set_defaults(func=cmd_robot_router)


def register(sub: Any) -> None:
    agent = sub.add_parser("agent", help="the on-robot agent over ROS 2 (zenoh or DDS)")
    agent_sub = agent.add_subparsers(dest="agent_command", required=True, metavar="SUBCOMMAND")
    _add_run(agent_sub)
    _add_find(agent_sub)
    _add_where(agent_sub)
    _add_replay(agent_sub)
    robot = sub.add_parser("robot", help="a stand-in robot and a zenoh router for it")
    robot_sub = robot.add_subparsers(dest="robot_command", required=True, metavar="SUBCOMMAND")
    _add_sim(robot_sub)
    _add_view(sub)
    _add_router(robot_sub)
