"""Nav2's NavigateToPose of either distro over ``--transport ros2`` (issue 44): Humble's result
(``std_msgs/Empty``) and Jazzy's (``error_code``, ``error_msg``) have one wire name and two
layouts, and Fast DDS dropped every Jazzy result at an agent that expected Humble's. The agent
(``[navigation] distro = "auto"``) reads the server's type hash on the graph and speaks its
distro; one configured for the other distro gets an error naming both, not a timeout."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from objsearch.ros.qos import DEFAULT
from objsearch.runtime.action import topics
from objsearch.runtime.agent_node import AgentNode
from objsearch.runtime.backends import open_transport
from objsearch.runtime.client import AgentClient
from objsearch.runtime.config import NavigationSettings, RuntimeConfig, Timeouts
from objsearch.runtime.errors import RuntimeConfigError
from objsearch.runtime.interfaces import NAVIGATE_TO_POSE, NAVIGATE_TO_POSE_JAZZY, wire_hashes
from objsearch.runtime.node import Node
from objsearch.runtime.requests import FindRequest
from objsearch.runtime.transport import Backend, TransportConfig

from .runtime_fixtures import Net, next_domain, objsearch, stop
from .searches import client_config, decisions, find_after_reset, in_process, robot_config

pytest.importorskip("rclpy")

#: Five searches of Table II's scene 1.
FIVE = [
    (1, "Apple", "kitchen-1"),
    (1, "Apple", "bedroom-1"),
    (1, "Cup", "living-1"),
    (1, "Cup", "kitchen-1"),
    (1, "Apple", "living-1"),
]


def toml(distro: str) -> str:
    return (
        f'[navigation]\ninterface = "navigate_to_pose"\ndistro = "{distro}"\n'
        "[timeouts]\nclaim_s = 0.1\n"  # one agent on its own domain: no claim to wait out
    )


@pytest.mark.parametrize("shape", ["humble", "jazzy"])
def test_five_searches_through_either_nav2(shape: str, tmp_path: Path) -> None:
    expected = in_process(tmp_path / "inproc", FIVE)
    domain = next_domain()
    net = Net("ros2", ["--transport", "ros2", "--domain-id", str(domain)])
    (tmp_path / "robot").mkdir()
    robot = objsearch(
        "robot",
        "sim",
        *net.args,
        *robot_config(tmp_path / "robot", toml(shape)),
        log=tmp_path / "robot.txt",
    )
    agent = objsearch(
        "agent",
        "run",
        *net.args,
        *robot_config(tmp_path, toml("auto")),
        "--log",
        str(tmp_path / "log"),
        log=tmp_path / "agent.txt",
    )
    got = []
    # The stand-in's Nav2 feedback, as a viewer of the action reads it (Humble's and Jazzy's
    # feedback are one layout).
    feedback: list[float] = []
    viewer = Node(open_transport(TransportConfig(Backend.ROS2, domain, node="nav2_viewer")))
    viewer.subscribe(
        topics("/navigate_to_pose")["feedback"],
        f"{NAVIGATE_TO_POSE}_FeedbackMessage",
        DEFAULT,
        lambda msg: feedback.append(float(msg.feedback.distance_remaining)),
    )
    try:
        with AgentClient(client_config(net)) as client:
            for scene, target, start in FIVE:
                r = find_after_reset(client, scene, target, start)
                assert r["ok"], r
                got.append(decisions(r))
    finally:
        viewer.close()
        stop(agent)
        robot_log = tmp_path / "robot.txt"
        if shape == "humble":
            # The same robot against an agent that expects Jazzy's result: named, at once.
            mismatch = mismatched_agent(tmp_path, domain, "jazzy", net)
            assert "result type is Humble's" in mismatch, mismatch
        stop(robot)
    assert got == expected
    assert feedback and 0.0 in feedback and max(feedback) > 0, feedback[:20]
    log = (tmp_path / "agent.txt").read_text()
    assert f"the server speaks {shape.title()}'s NavigateToPose" in log
    assert "Traceback" not in log and "Traceback" not in robot_log.read_text()


def mismatched_agent(tmp_path: Path, domain: int, distro: str, net: Net) -> str:
    """An agent of this process configured for ``distro``, asked one search: its error."""
    config = RuntimeConfig(
        transport=TransportConfig(backend=Backend.ROS2, domain_id=domain),
        navigation=NavigationSettings(interface="navigate_to_pose", distro=distro),
        timeouts=replace(Timeouts(), claim_s=0.1),
    )
    if distro == "jazzy":  # this process speaks Humble's (a process speaks one): a process of
        # its own then, as a user would run it
        agent = objsearch(
            "agent",
            "run",
            *net.args,
            *robot_config(tmp_path, toml(distro)),
            "--log",
            str(tmp_path / "mismatch-log"),
            log=tmp_path / "mismatch.txt",
        )
        try:
            with AgentClient(client_config(net)) as client:
                r = find_after_reset(client, 1, "Apple", "kitchen-1")
        finally:
            stop(agent)
        assert not r["ok"]
        return str(r["error"])
    node = AgentNode(config, tmp_path / "mismatch-log")
    try:
        r = node.handle(FindRequest(id="x", target="Apple"))
    finally:
        node.close()
    assert not r["ok"]
    return str(r["error"])


def test_a_jazzy_server_meets_an_agent_set_to_humble_with_a_named_error(tmp_path: Path) -> None:
    """The other way round, the agent in this process (Humble's build, as every in-process
    test here) against a Jazzy stand-in."""
    domain = next_domain()
    net = Net("ros2", ["--transport", "ros2", "--domain-id", str(domain)])
    robot = objsearch(
        "robot", "sim", *net.args, *robot_config(tmp_path, toml("jazzy")), log=tmp_path / "r.txt"
    )
    try:
        error = mismatched_agent(tmp_path, domain, "humble", net)
    finally:
        stop(robot)
    jazzy = wire_hashes(NAVIGATE_TO_POSE_JAZZY)["GetResult_Response"]
    humble = wire_hashes(NAVIGATE_TO_POSE)["GetResult_Response"]
    assert error.startswith(
        f"the /navigate_to_pose server's result type is Jazzy's ({jazzy}), not Humble's "
        f"({humble}) that [navigation] distro = 'humble' asks for: set it to 'jazzy' or 'auto'"
    )


def test_jazzy_needs_the_ros2_transport() -> None:
    config = RuntimeConfig(
        transport=TransportConfig(backend=Backend.DDS),
        navigation=NavigationSettings(interface="navigate_to_pose", distro="jazzy"),
    )
    with pytest.raises(RuntimeConfigError, match="distro = 'jazzy' needs --transport ros2"):
        config.check()
