"""The answer carries the diagnosis (issue 44): what the agent can see wrong on the graph — a
publisher of another type on a topic it reads, a QoS mismatch — is named in the answer the
client gets, not only in the agent's log. Before, a PoseStamped publisher on /odom was reported
to the client as "nothing was ever heard from the robot"."""

from __future__ import annotations

import os
import threading
import time
from contextlib import suppress
from dataclasses import replace
from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import read_log
from objsearch.runtime.agent_node import AgentNode
from objsearch.runtime.config import RuntimeConfig, Timeouts
from objsearch.runtime.requests import FindRequest
from objsearch.runtime.transport import Backend, TransportConfig

from .runtime_fixtures import STARTUP_S, next_domain

rclpy = pytest.importorskip("rclpy")


def test_a_wrong_type_and_a_qos_mismatch_are_named_in_the_answer(tmp_path: Path) -> None:
    from geometry_msgs.msg import PoseStamped
    from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from vision_msgs.msg import Detection2DArray

    domain = next_domain()
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    robot = rclpy.create_node("odd_robot", context=context)
    executor = MultiThreadedExecutor(num_threads=2, context=context)
    executor.add_node(robot)

    def spin() -> None:
        with suppress(ExternalShutdownException):
            executor.spin()

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    # Its odometry as PoseStamped, its detector's output best effort (the agent reads reliable).
    odom = robot.create_publisher(PoseStamped, "/odom", 10)
    best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
    robot.create_publisher(Detection2DArray, "/objsearch/detections", best_effort)
    config = RuntimeConfig(
        transport=TransportConfig(backend=Backend.ROS2, domain_id=domain),
        timeouts=replace(Timeouts(), claim_s=0.1, robot_s=3.0),
    )
    agent = AgentNode(config, tmp_path / "log")
    try:
        deadline = time.monotonic() + STARTUP_S
        while len(agent.node.diagnosis()) < 2:  # until discovery has shown both
            assert time.monotonic() < deadline, agent.node.diagnosis()
            odom.publish(PoseStamped())
            time.sleep(0.05)
        result = agent.handle(FindRequest(id="x", target="Apple"))
    finally:
        agent.close()
        executor.shutdown(timeout_sec=5.0)
        robot.destroy_node()
        context.try_shutdown()
        spinner.join(5.0)
    assert not result["ok"]
    error = result["error"]
    assert error.startswith("no fresh pose on /odom within 3 s; nothing was ever heard")
    assert (
        "on the graph: /odom has a publisher of geometry_msgs/msg/PoseStamped (node /odd_robot), "
        "which this agent does not read: it reads nav_msgs/msg/Odometry"
    ) in error
    assert (
        "QoS mismatch on /objsearch/detections: a writer offers QoS this reader (reliable, "
        "volatile, depth 10) cannot match: reliability differs"
    ) in error
    # No pose, so no task began: nothing of it in the log (a search that fails later logs the
    # same text as its search_failed reason).
    assert not [e for e in read_log(tmp_path / "log", store=STORE) if e.type == "task_started"]
