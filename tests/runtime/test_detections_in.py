"""Scored detections from a detector node (runtime/detections_in.py): the stand-in robot sends
its modelled detector's ``Detection3DArray`` in the camera's optical frame, the agent reads them
through TF and camera info, a bag recorded of that session (rosbags, MCAP) replays through the
offline pipeline (pipeline/bags/views.py) to the same decisions; over ``--transport ros2`` a plain
rclpy detector node's ``Detection3DArray`` reach the agent."""

from __future__ import annotations

import json
import os
import select
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from rosbags.rosbag2 import StoragePlugin

from objsearch.agent.catalogue import STORE, RunStarted, decode
from objsearch.cli import main
from objsearch.events import read_log
from objsearch.pipeline.bags.views import decisions, read_recording, replay_recording
from objsearch.ros.mcapstore import rosbag2_writer
from objsearch.ros.qos import QoS
from objsearch.runtime import messages as m
from objsearch.runtime.backends import open_transport
from objsearch.runtime.client import AgentClient

from .runtime_fixtures import STARTUP_S, Net, next_domain, objsearch, stop
from .searches import client_config, find_after_reset, robot_config

THREE_D = '[detections]\ninput = "3d"\n'
#: What a recorder takes (the topics a replay needs, plus the goals for the reader's sake).
RECORDED = {
    "/odom": m.ODOMETRY,
    "/tf": m.TF,
    "/camera/color/camera_info": "sensor_msgs/msg/CameraInfo",
    "/objsearch/detections": "vision_msgs/msg/Detection3DArray",
    "/objsearch/events": m.EVENT,
}
# Table II scene 2, kept short: two searches of the realistic detector's noise.
TRIALS = [(2, "Cup", "kitchen-1"), (2, "Apple", "living-1")]


class Recorder:
    """``ros2 bag record`` of a few topics: every message's CDR bytes into a rosbag2 MCAP bag."""

    def __init__(self, net: Net, path: Path) -> None:
        self.writer = rosbag2_writer(path, StoragePlugin.MCAP)
        self.writer.open()
        self.lock = threading.Lock()
        self.counts: dict[str, int] = {}
        self.conns: dict[str, Any] = {}
        self.transport = open_transport(client_config(net).transport)
        for topic, msgtype in RECORDED.items():
            self.conns[topic] = self.writer.add_connection(topic, msgtype, typestore=m.store())
            qos = QoS.parse("reliable,volatile,1000")
            self.transport.subscribe(topic, msgtype, qos, self._on(topic))

    def _on(self, topic: str) -> Any:
        def write(data: bytes) -> None:
            import time

            with self.lock:
                if self.writer is None:
                    return
                self.writer.write(self.conns[topic], time.time_ns(), data)
                self.counts[topic] = self.counts.get(topic, 0) + 1

        return write

    def close(self) -> None:
        self.transport.close()
        with self.lock:
            self.writer.close()
            self.writer = None  # type: ignore[assignment]


@pytest.mark.slow
# One transport is enough: the recorded bytes are the same over dds.
@pytest.mark.parametrize("net", ["zenoh"], indirect=True)
def test_a_recorded_bag_of_scored_3d_detections_replays_to_the_same_decisions(
    net: Net, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = robot_config(tmp_path, THREE_D)
    bag = tmp_path / "session"
    recorder = Recorder(net, bag)
    robot = objsearch(
        "robot",
        "sim",
        *net.args,
        *config,
        "--perception",
        "realistic",
        "--seed",
        "3",
        log=tmp_path / "robot.txt",
    )
    agent = objsearch(
        "agent",
        "run",
        *net.args,
        *config,
        "--perception",
        "realistic",
        "--log",
        str(tmp_path / "log"),
        log=tmp_path / "agent.txt",
    )
    results = []
    try:
        with AgentClient(client_config(net)) as client:
            for scene, target, start in TRIALS:
                r = find_after_reset(client, scene, target, start)
                assert r["ok"], (r, (tmp_path / "agent.txt").read_text()[-3000:])
                results.append(r)
    finally:
        stop(agent)
        stop(robot)
        recorder.close()
    live = list(read_log(tmp_path / "log", store=STORE))
    (run,) = [decode(e, RunStarted) for e in live if e.type == "run_started"]
    assert run.params["perception"]["preset"] == "realistic"
    # The noise reached the agent: scores below 1 on its detection events (v3).
    scored = [e.payload["score"] for e in live if e.type == "detection"]
    assert scored and min(scored) < 1.0, scored
    assert recorder.counts["/objsearch/detections"] >= len(scored) // 10

    recording = read_recording(bag, input="3d")
    assert recording.rejected == {}
    # The bag holds every event the agent logged, as logged.
    assert [e.event_id for e in recording.agent] == [e.event_id for e in live]
    replay = replay_recording(recording, "paper", tmp_path / "replayed")
    assert replay.tasks == len(TRIALS)
    assert decisions(replay.replayed) == decisions(live)
    ended = [e.payload for e in replay.replayed if e.type == "task_ended"]
    assert [round(p["path_length"], 4) for p in ended] == [
        round(r["path_length"], 4) for r in results
    ]
    # The same from the command line, with the robot.toml the agent ran with.
    capsys.readouterr()
    assert main(["agent", "replay", str(bag), *config, "--format", "json", "--no-progress"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert (doc["same"], doc["tasks"], doc["decisions"]) == (True, 2, len(decisions(live)))
    # A bag of another detector's input reads no views: a clear error, not a replay of nothing.
    assert main(["agent", "replay", str(bag), "--no-progress"]) == 2
    assert "no camera views could be read (vision_msgs/msg/Detection2DArray" in (
        capsys.readouterr().err
    )


DETECTOR = Path(__file__).with_name("ros_detector.py")
#: The stand-in robot's camera arrays go here, read only by the detector node of the test, and
#: offered transient-local: the robot sends each view once, and the node can see only its own
#: side of the match (ros_detector.py says why).
RAW = "/camera/detections_raw"
RAW_QOS = "reliable,transient_local,10"


@pytest.mark.slow
def test_a_plain_rclpy_detector_nodes_3d_detections_reach_the_agent_over_ros2(
    tmp_path: Path,
) -> None:
    """``vision_msgs/Detection3DArray`` over ``--transport ros2`` (issue 45's seam; the type
    support was not generated for rclpy before): the arrays the agent reads are published by a
    ROS 2 node of plain rclpy (``ros_detector.py``, no objsearch module). The stand-in robot gives
    odometry, TF, camera info and its camera's arrays, on a topic only that node reads. The
    searches begin once the node's publisher has matched the agent's subscription: the first view
    (the first search's container opening) was lost when the robot sent it before (issue 45)."""
    pytest.importorskip("rclpy")
    domain = next_domain()
    net = Net("ros2", ["--transport", "ros2", "--domain-id", str(domain)])
    (tmp_path / "robot").mkdir()
    (tmp_path / "agent").mkdir()
    robot_toml = robot_config(
        tmp_path / "robot",
        f'{THREE_D}[topics]\ndetections = "{RAW}"\n[qos]\ndetections = "{RAW_QOS}"\n',
    )
    detector = subprocess.Popen(
        [sys.executable, str(DETECTOR), str(domain), RAW, "/objsearch/detections", str(STARTUP_S)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    robot = objsearch("robot", "sim", *net.args, *robot_toml, log=tmp_path / "robot.txt")
    agent = objsearch(
        "agent",
        "run",
        *net.args,
        *robot_config(tmp_path / "agent", THREE_D),
        "--log",
        str(tmp_path / "log"),
        log=tmp_path / "agent.txt",
    )
    results = []
    try:
        assert detector.stdout is not None
        # Ready: its publisher matched the agent's subscription, its subscription the robot's.
        ready = detector.stdout.readline()
        assert ready == "ready\n", ready
        with AgentClient(client_config(net)) as client:
            for scene, target, start in TRIALS:
                r = find_after_reset(client, scene, target, start)
                assert r["ok"], (r, (tmp_path / "agent.txt").read_text()[-3000:])
                results.append(r)
    finally:
        stop(agent)
        stop(robot)
        out, _ = detector.communicate(timeout=STARTUP_S)
    published = json.loads(out.strip().splitlines()[-1])
    assert published["objsearch_modules"] == []  # the detector is a ROS user's node
    assert published["arrays"] > 0 and published["detections"] > 0, published
    live = list(read_log(tmp_path / "log", store=STORE))
    detections = [e.payload for e in live if e.type == "detection"]
    assert detections, "the agent took no detection from the detector node"
    assert {d["object_class"] for d in detections} >= {"Cup", "Apple"}, detections
    assert all(r["success"] for r in results), results


def test_the_detector_node_says_ready_only_once_both_its_topics_are_matched() -> None:
    """What the test above waits for: ``ros_detector.py`` says ``ready`` only when its publisher
    has a matched subscriber and its subscription a matched publisher. It used to say so as soon
    as its node existed, and a view the robot sent before the matching never reached the agent
    (issue 45)."""
    rclpy = pytest.importorskip("rclpy")
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from vision_msgs.msg import Detection3DArray

    domain = next_domain()
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    out = "/objsearch/detections"

    def detector(match_s: float) -> subprocess.Popen[str]:
        return subprocess.Popen(
            [sys.executable, str(DETECTOR), str(domain), RAW, out, str(match_s)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )

    # Alone on its domain: at the deadline, what is missing.
    alone = detector(1.0)
    first, _ = alone.communicate(timeout=STARTUP_S)
    assert first.splitlines()[0] == (
        f"not matched after 1 s: 0 subscriber(s) of {out}, 0 publisher(s) of {RAW}"
    )
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    peer = rclpy.create_node("agent_and_robot", context=context)
    node = detector(STARTUP_S)
    try:
        assert node.stdout is not None
        agent_side = peer.create_subscription(Detection3DArray, out, lambda _: None, 10)
        deadline = time.monotonic() + STARTUP_S
        while not agent_side.get_publisher_count():  # the node is on the graph, with its output
            assert time.monotonic() < deadline, "the detector node's publisher never matched"
            time.sleep(0.01)
        # No publisher of its input yet: not ready (nothing to read).
        assert select.select([node.stdout], [], [], 0.0)[0] == []
        latched = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        peer.create_publisher(Detection3DArray, RAW, latched)
        assert node.stdout.readline() == "ready\n"
    finally:
        node.communicate(timeout=STARTUP_S)
        peer.destroy_node()
        context.try_shutdown()
