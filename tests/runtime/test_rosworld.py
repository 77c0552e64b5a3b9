"""Which camera view answers which robot command (runtime/rosworld.py), against a scripted robot
on one real in-process Zenoh session: a robot whose camera lags its odometry must not hand a look
the view of the command before it."""

from __future__ import annotations

import dataclasses
import queue
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest

pytest.importorskip("zenoh")

from objsearch.agent.geometry import Pose
from objsearch.agent.session import load_context
from objsearch.agent.world import Detection
from objsearch.runtime import messages as m
from objsearch.runtime.backends import open_transport
from objsearch.runtime.config import RuntimeConfig, Timeouts
from objsearch.runtime.node import Node
from objsearch.runtime.rosworld import RobotLink, RosWorld
from objsearch.runtime.transport import TransportConfig

S = 10**9
#: How long the scripted camera lags the odometry (unless the next goal comes first).
LAG_S = 0.3


@pytest.fixture
def node() -> Iterator[Node]:
    n = Node(open_transport(TransportConfig(connect=(), listen=("tcp/127.0.0.1:0",))))
    yield n
    n.close()


def seen(cls: str) -> tuple[Detection, ...]:
    return (Detection(cls, f"{cls}|1", 900.0, (1.0, 2.0, 0.5), 0.9, ((cls, 0.9),)),)


class LaggingCamera:
    """A robot that answers each goal with its odometry at once and its camera view
    :data:`LAG_S` later, or when the next goal comes if that is sooner (a detector slower than
    the agent's next command). Each command takes one second of robot time; a goal's view shows
    ``views[goal number]``."""

    def __init__(self, node: Node, config: RuntimeConfig, start: Pose, views: list[str]) -> None:
        t, q = config.topics, config.qos
        self.odom = node.publisher(t.odometry, m.ODOMETRY, q.odometry)
        self.views = node.publisher(t.detections, m.DETECTIONS, q.detections)
        self.classes = views
        self.ns = S
        self.pose = start
        self.held: Any = None
        self.goals: queue.Queue[Pose] = queue.Queue()
        node.subscribe(t.goal, m.POSE_STAMPED, q.goal, self._on_goal)
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _on_goal(self, msg: Any) -> None:
        self.goals.put(m.pose_of_pose_stamped(msg))

    def _run(self) -> None:
        n = 0
        while not self._stop.is_set():
            try:
                goal = self.goals.get(timeout=LAG_S)
            except queue.Empty:
                self._late_view()
                self.odom.publish(m.odometry(self.pose, self.ns))  # heartbeat
                continue
            self._late_view()
            self.ns += S
            self.pose = goal
            self.odom.publish(m.odometry(self.pose, self.ns))
            self.held = m.detections(self.ns, self.pose, seen(self.classes[n]))
            n += 1

    def _late_view(self) -> None:
        if self.held is not None:
            self.views.publish(self.held)
            self.held = None

    def __enter__(self) -> LaggingCamera:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self.thread.join()


def test_a_look_after_a_turn_waits_for_its_own_view_not_the_turns(node: Node) -> None:
    ctx = load_context("paper")
    start = ctx.home.start("kitchen-1")
    config = dataclasses.replace(
        RuntimeConfig(), timeouts=dataclasses.replace(Timeouts(), detections_s=3.0, attempts=2)
    )
    link = RobotLink(node, config)
    world = RosWorld(link, ctx.navmap)
    turned = Pose(start.x, start.y, start.yaw + 1.0)
    with LaggingCamera(node, config, start, ["Apple", "Cup", "Bowl"]):
        world.wait_for_robot(10.0)
        # A turn in place nobody reads the view of (a navigation's final turn), then a look the
        # same way from the same place: the robot is there already, so arrival is at once.
        assert world._step(turned, 0.0, view=False) == ()
        # The turn's view (Apple, stamped at the turn's arrival) comes in after the look was sent;
        # the look's own is the one after it.
        assert [d.object_class for d in world.look(turned.yaw)] == ["Cup"]


#: How long the slow robot takes to answer a goal (its odometry and view both).
ANSWER_S = 0.3


class SlowRobot:
    """A robot that answers each goal :data:`ANSWER_S` later, with its odometry at the goal one
    second of robot time on and then that goal's view (``views[goal number]``), and otherwise
    repeats its last odometry as a heartbeat."""

    def __init__(self, node: Node, config: RuntimeConfig, start: Pose, views: list[str]) -> None:
        t, q = config.topics, config.qos
        self.odom = node.publisher(t.odometry, m.ODOMETRY, q.odometry)
        self.views = node.publisher(t.detections, m.DETECTIONS, q.detections)
        self.classes = views
        self.ns = S
        self.pose = start
        self.goals: queue.Queue[Pose] = queue.Queue()
        node.subscribe(
            t.goal, m.POSE_STAMPED, q.goal, lambda msg: self.goals.put(m.pose_of_pose_stamped(msg))
        )
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        n = 0
        while not self._stop.is_set():
            try:
                goal = self.goals.get(timeout=0.1)
            except queue.Empty:
                self.odom.publish(m.odometry(self.pose, self.ns))
                continue
            time.sleep(ANSWER_S)
            self.ns += S
            self.pose = goal
            self.odom.publish(m.odometry(self.pose, self.ns))
            self.views.publish(m.detections(self.ns, self.pose, seen(self.classes[n])))
            n += 1

    def __enter__(self) -> SlowRobot:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self.thread.join()


def test_a_turn_already_within_tolerance_waits_for_the_robots_answer_to_it(node: Node) -> None:
    """Issue 45: a turn so small that the robot is within tolerance of it already must not
    return on the pose from before it; else the look sent next, at the same clock, took the
    turn's own late view or the look's own depending on timing (and a bag's replay could not
    tell which)."""
    ctx = load_context("paper")
    start = ctx.home.start("kitchen-1")
    config = dataclasses.replace(
        RuntimeConfig(), timeouts=dataclasses.replace(Timeouts(), detections_s=3.0, attempts=2)
    )
    link = RobotLink(node, config)
    world = RosWorld(link, ctx.navmap)
    nudged = Pose(start.x, start.y, start.yaw + 0.015)  # within the yaw tolerance already
    with SlowRobot(node, config, start, ["Apple", "Cup", "Bowl"]):
        world.wait_for_robot(10.0)
        assert world._step(nudged, 0.0, view=False) == ()
        assert link.pose_ns == 2 * S  # the robot's answer to the turn
        looks = [[d.object_class for d in world.look(nudged.yaw)] for _ in range(2)]
        assert looks == [["Cup"], ["Bowl"]]
