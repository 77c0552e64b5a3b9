"""The agent's :class:`~objsearch.agent.world.World` on a ROS 2 robot.

Navigation goes waypoint by waypoint along the agent's own viewpoint graph: each waypoint is a
``geometry_msgs/PoseStamped`` on the goal topic (``/goal_pose``, what Nav2's BT navigator and
RViz's 2D Goal Pose use); arrival is odometry within tolerance of it; the camera view taken there
is the first ``vision_msgs/Detection2DArray`` stamped at or after arrival. Stopping between
waypoints is how the detector "cancels" a goal. Each goal carries a unique stamp, so sending it
again after a lost message is harmless: the robot answers a repeated goal without moving.

Every wait has a deadline; a robot that does not answer raises :class:`RobotError` saying what
was asked, what was last heard and when.
"""

from __future__ import annotations

import itertools
import math
import threading
import time
from collections.abc import Callable
from typing import Any

from objsearch.agent.geometry import Point, Pose, heading, wrap_angle
from objsearch.agent.navmap import NavigationMap
from objsearch.agent.world import Detection, DetectionHandler, Navigation
from objsearch.runtime import messages as m
from objsearch.runtime.config import RuntimeConfig
from objsearch.runtime.errors import RobotError
from objsearch.runtime.node import Node, Requester


class RobotLink:
    """What the agent hears from the robot: its latest pose and clock, and its camera views."""

    def __init__(self, node: Node, config: RuntimeConfig) -> None:
        self.config = config
        t, q = config.topics, config.qos
        self._cond = threading.Condition()
        self.pose: Pose | None = None
        self.pose_ns = 0
        self.pose_count = 0  # odometry messages received
        self.clock_ns = 0
        self.heard_at = 0.0  # monotonic time of the last message from the robot
        self._views: list[tuple[int, int, tuple[Detection, ...]]] = []  # (arrival no, stamp, dets)
        self._received = itertools.count()
        self.goal_pub = node.publisher(t.goal, m.POSE_STAMPED, q.goal)
        self.opener = Requester(node, t.open, t.open_result, q.requests)
        node.subscribe(t.odometry, m.ODOMETRY, q.odometry, self._on_odometry)
        node.subscribe(t.detections, m.DETECTIONS, q.detections, self._on_detections)

    def _on_odometry(self, msg: Any) -> None:
        pose = m.pose_of_odometry(msg)
        ns = m.stamp_ns(msg.header)
        with self._cond:
            if ns >= self.pose_ns:
                self.pose, self.pose_ns = pose, ns
            self.pose_count += 1
            self.clock_ns = max(self.clock_ns, ns)
            self.heard_at = time.monotonic()
            self._cond.notify_all()

    def _on_detections(self, msg: Any) -> None:
        dets = m.detections_of(msg)
        ns = m.stamp_ns(msg.header)
        with self._cond:
            self._views.append((next(self._received), ns, dets))
            self.clock_ns = max(self.clock_ns, ns)
            self.heard_at = time.monotonic()
            self._cond.notify_all()

    def mark(self) -> int:
        """A point in the stream of views: only views received after it count."""
        with self._cond:
            return next(self._received)

    def wait(self, ready: Callable[[], Any], timeout_s: float) -> Any:
        """Wait until ``ready()`` (called under the lock) is truthy; None on timeout, or when the
        robot has been silent for longer than ``timeouts.robot_s``."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while True:
                value = ready()
                if value:
                    return value
                now = time.monotonic()
                if now >= deadline or (
                    self.heard_at and now - self.heard_at > self.config.timeouts.robot_s
                ):
                    return None
                self._cond.wait(min(deadline - now, 0.2))

    def view_after(self, mark: int, stamp_ns: int) -> tuple[Detection, ...] | None:
        for received, ns, dets in self._views:
            if received > mark and ns >= stamp_ns:
                return dets
        return None

    def silence(self) -> str:
        if not self.heard_at:
            return "nothing was ever heard from the robot"
        return (
            f"last heard from the robot {time.monotonic() - self.heard_at:.1f} s ago "
            f"at pose ({self.pose.x:.2f}, {self.pose.y:.2f}, {self.pose.yaw:.2f})"
            if self.pose
            else "no odometry yet"
        )


class RosWorld:
    def __init__(self, link: RobotLink, navmap: NavigationMap) -> None:
        self.link = link
        self.navmap = navmap
        self._goal_ids = itertools.count(1)
        self.timeouts = link.config.timeouts
        #: The last pose the robot was sent to (or told it turned to): odometry within tolerance
        #: of it reads as exactly it, so the agent plans on the numbers it asked for.
        self._commanded: Pose | None = None

    def wait_for_robot(self, timeout_s: float) -> Pose:
        pose = self.link.wait(lambda: self.link.pose, timeout_s)
        if pose is None:
            raise RobotError(
                f"no odometry on {self.link.config.topics.odometry} within {timeout_s:g} s: "
                "is the robot up, on the same transport and domain, with matching QoS?"
            )
        return pose  # type: ignore[no-any-return]

    def fresh_pose(self, timeout_s: float, not_before_ns: int = 0) -> Pose:
        """Wait for odometry received after this call and stamped at or after ``not_before_ns``
        (a task starts from where the robot is now, not from a message still in flight)."""
        seen = self.link.pose_count

        def fresh() -> bool:
            return self.link.pose_count > seen and self.link.pose_ns >= not_before_ns

        if not self.link.wait(fresh, timeout_s):
            raise RobotError(
                f"no fresh odometry on {self.link.config.topics.odometry} within {timeout_s:g} s; "
                f"{self.link.silence()}"
            )
        self._commanded = None
        return self.pose()

    def pose(self) -> Pose:
        pose = self.link.pose
        if pose is None:
            pose = self.wait_for_robot(self.timeouts.robot_s)
        if self._commanded is not None and self._at(self._commanded):
            return self._commanded
        return self.navmap_pose(pose)

    def navmap_pose(self, pose: Pose) -> Pose:
        """Odometry snapped to the viewpoint it is at (the graph the agent plans on)."""
        point = min(self.navmap.room_of, key=lambda p: (p.x - pose.x) ** 2 + (p.y - pose.y) ** 2)
        if math.hypot(point.x - pose.x, point.y - pose.y) <= self.timeouts.tolerance_m:
            return Pose(point.x, point.y, pose.yaw)
        return pose

    def now_ns(self) -> int:
        return self.link.clock_ns

    def _at(self, goal: Pose) -> bool:
        p = self.link.pose
        tol = self.timeouts
        return (
            p is not None
            and math.hypot(p.x - goal.x, p.y - goal.y) <= tol.tolerance_m
            and abs(wrap_angle(p.yaw - goal.yaw)) <= tol.tolerance_rad
        )

    def _drive(self, goal: Pose, *, view: bool) -> tuple[Detection, ...]:
        """Send one goal (again if need be) and wait for arrival and, with ``view``, the view."""
        goal_stamp = time.time_ns() + next(self._goal_ids)  # unique: the goal's identity
        msg = m.pose_stamped(goal, goal_stamp)
        mark = self.link.mark()
        t = self.timeouts
        for _attempt in range(t.attempts):
            self.link.goal_pub.publish(msg)
            arrived = self.link.wait(
                lambda: self._at(goal) and (self.link.pose_ns or -1), t.arrival_s
            )
            if not arrived:
                continue
            self._commanded = goal
            if not view:
                return ()
            arrival_ns = self.link.pose_ns

            def viewed(since: int = arrival_ns) -> bool:
                return self.link.view_after(mark, since) is not None

            if self.link.wait(viewed, t.detections_s):
                view_dets = self.link.view_after(mark, arrival_ns)
                assert view_dets is not None
                return view_dets
        raise RobotError(
            f"the robot did not {'reach' if not view else 'reach and view from'} "
            f"({goal.x:.2f}, {goal.y:.2f}, yaw {goal.yaw:.2f}) after {t.attempts} attempts "
            f"of {t.arrival_s:g} s; {self.link.silence()}"
        )

    def navigate(
        self,
        goal: Point,
        *,
        on_detection: DetectionHandler | None = None,
        final_yaw: float | None = None,
    ) -> Navigation:
        here = self.pose()
        path = self.navmap.path(here.point, goal)
        walked = [path[0]]
        rooms = [self.navmap.room_of[path[0]]]
        metres = 0.0
        yaw = here.yaw
        interrupted = False
        for a, b in itertools.pairwise(path):
            if self.navmap.is_teleport(a, b):
                rooms.append(self.navmap.room_of[b])
            else:
                yaw = heading(a, b)
                metres += self.navmap.graph.edges[a, b]["weight"]
            dets = self._drive(Pose(b.x, b.y, yaw), view=True)
            walked.append(b)
            pose = Pose(b.x, b.y, yaw)
            if on_detection is not None:
                stops = [on_detection(det, pose) for det in dets]
                if any(stops):
                    interrupted = True
                    break
        end = Pose(walked[-1].x, walked[-1].y, yaw)
        if final_yaw is not None and not interrupted:
            self._drive(Pose(end.x, end.y, final_yaw), view=False)
            end = Pose(end.x, end.y, final_yaw)
        return Navigation(tuple(walked), metres, end, tuple(rooms), interrupted)

    def look(self, yaw: float) -> tuple[Detection, ...]:
        here = self.pose()
        return self._drive(Pose(here.x, here.y, yaw), view=True)

    def open(self, static_id: str) -> tuple[Detection, ...]:
        mark = self.link.mark()
        t = self.timeouts
        try:
            result = self.link.opener.call(
                {"static_id": static_id},
                timeout_s=t.arrival_s * t.attempts,
                what=f"open {static_id!r}",
            )
        except RobotError as exc:
            raise RobotError(f"{exc}; {self.link.silence()}") from None
        if not result.get("ok"):
            raise RobotError(f"the robot could not open {static_id!r}: {result.get('error')}")
        stamp = int(result.get("stamp_ns", 0))
        here = self.pose()
        self._commanded = Pose(here.x, here.y, float(result.get("yaw", here.yaw)))
        dets = self.link.wait(lambda: self.link.view_after(mark, stamp) is not None, t.detections_s)
        if not dets:
            raise RobotError(
                f"no camera view after opening {static_id!r} within {t.detections_s:g} s; "
                f"{self.link.silence()}"
            )
        view = self.link.view_after(mark, stamp)
        assert view is not None
        # The robot turned to the container: wait for the odometry that says so.
        self.link.wait(lambda: self.link.pose_ns >= stamp, t.detections_s)
        return view
