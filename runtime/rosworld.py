"""The agent's :class:`~objsearch.agent.world.World` on a ROS 2 robot.

Navigation goes waypoint by waypoint along the agent's own viewpoint graph: each waypoint is a
``geometry_msgs/PoseStamped`` on the goal topic (``/goal_pose``, what Nav2's BT navigator and
RViz's 2D Goal Pose use); arrival is odometry within tolerance of it; the camera view taken there
is the first detections message received after the goal was sent, stamped at or after arrival
*and* later than the robot's clock as the agent had heard it when it sent the goal
(``objsearch.ros.detections.view_not_before``). Arrival is a pose at the goal stamped *after*
that clock, even when the robot is at the goal already: its answer to this goal, not an old pose.
So a command returns only once the robot's answer to it has been heard, and the clock the next
command is sent at does not depend on how fast that answer travelled (a turn already within
tolerance that returned on the old pose let the next look take the turn's own view or not,
depending on timing, and a bag's replay could not tell which: issue 45); a view of the command
before (a turn whose view nobody waited for, still in flight) never passes for this one's. So
each pose and view must be stamped later than anything the robot sent before the goal, as a
camera's frames and a robot's odometry are (the stand-in robot spends one camera frame on a
teleport between room entries). Stopping between waypoints is how the detector "cancels" a
goal. Each goal carries a unique stamp, so sending it again after a lost message is harmless:
the robot answers a repeated goal without moving.

With ``[navigation] interface = "navigate_to_pose"`` each waypoint is a goal of Nav2's action
instead: arrival is the goal's SUCCEEDED result (Nav2's own tolerance decides), the view is the
first one stamped at or after it, by the same rule; a goal without a result in ``arrival_s``
is cancelled (``cancel_goal``) and sent again as a new goal; a rejected or aborted goal fails the
search.
The pose comes from odometry or, with ``[pose] source = "tf"``, from map → base_link in /tf.

Every wait has a deadline; a robot that does not answer raises :class:`RobotError` saying what
was asked, what was last heard and when.
"""

from __future__ import annotations

import itertools
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from objsearch.agent.geometry import Point, Pose, wrap_angle
from objsearch.agent.navigation import walk_path
from objsearch.agent.navmap import NavigationMap
from objsearch.agent.world import Detection, DetectionHandler, Navigation
from objsearch.ros.detections import view_not_before
from objsearch.ros.errors import TransformError
from objsearch.ros.tf import TransformBuffer
from objsearch.runtime import messages as m
from objsearch.runtime.action import STATUS_NAMES, STATUS_SUCCEEDED, ActionClient, new_goal_id
from objsearch.runtime.config import RuntimeConfig
from objsearch.runtime.detections_in import DetectionInput
from objsearch.runtime.errors import MessageError, RobotError, SearchCancelled
from objsearch.runtime.interfaces import NAV2_DISTROS, NAVIGATE_TO_POSE, wire_hashes
from objsearch.runtime.node import Node, Requester
from objsearch.runtime.requests import OpenResult, parse_open_result

log = logging.getLogger("objsearch.agent")

#: Camera views kept for :meth:`RobotLink.view_after` (the newest; a search waits for one view
#: at a time, so this only bounds memory over a long run).
VIEWS_KEPT = 1024

#: TF samples older than this (robot time) behind the newest are dropped (tf2 keeps 10 s).
TF_CACHE_NS = 10 * 10**9


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
        # (arrival no, stamp, dets) of the latest views
        self._views: deque[tuple[int, int, tuple[Detection, ...]]] = deque(maxlen=VIEWS_KEPT)
        self._received = itertools.count()
        nav = config.navigation
        self._node = node
        #: Nav2's action client, made at the first goal once the server's type is known (nav2).
        self.navigator: ActionClient | None = None
        if nav.interface != "navigate_to_pose":
            self.goal_pub = node.publisher(t.goal, m.POSE_STAMPED, q.goal)
        self.opener: Requester[OpenResult] = Requester(
            node, t.open, t.open_result, q.requests, parse_open_result
        )
        if config.pose.source == "tf":
            self.tf = TransformBuffer()
            node.subscribe(t.tf, m.TF, q.tf, self._on_tf)
            node.subscribe(t.tf_static, m.TF, q.tf_static, lambda msg: self._on_tf(msg, True))
        else:
            node.subscribe(t.odometry, m.ODOMETRY, q.odometry, self._on_odometry)
        # The detector's views, in the map frame (runtime/detections_in.py, [detections] input).
        self.detections = DetectionInput(node, config, self._on_view)

    def nav2(self) -> ActionClient:
        """The client of Nav2's action, of the distro ``[navigation] distro`` names, or (auto)
        of the server's: read from the type hash its get_result reply writer carries on the
        graph. A server of the other distro is an error naming both, at the first goal, rather
        than results that never arrive (Fast DDS drops a result larger than the type it
        expects)."""
        if self.navigator is None:
            nav = self.config.navigation
            self.navigator = ActionClient(self._node, nav.action, self._nav2_type())
        return self.navigator

    def _nav2_type(self) -> str:
        from objsearch.runtime.action import topics

        nav, robot_s = self.config.navigation, self.config.timeouts.robot_s
        known = {d: wire_hashes(t)["GetResult_Response"] for d, t in NAV2_DISTROS.items()}
        hashes_of = getattr(self._node.transport, "service_type_hashes", None)
        service = topics(nav.action)["get_result"]
        seen: list[str] = []
        if hashes_of is not None:
            deadline = time.monotonic() + robot_s
            while not (seen := hashes_of(service)) and time.monotonic() < deadline:
                time.sleep(0.05)
        kinds = [d for d, h in known.items() if h in seen]

        def shapes() -> str:
            named = [f"{d.title()}'s ({known[d]})" for d in kinds]
            other = [h for h in seen if h not in known.values()]
            return ", ".join(named + [f"unknown ({h})" for h in other])

        if nav.distro == "auto":
            if hashes_of is None:
                log.info(
                    "%s: this transport shows no type hashes; speaking Humble's NavigateToPose "
                    "(set [navigation] distro for another)",
                    nav.action,
                )
                return NAVIGATE_TO_POSE
            if not seen:
                raise RobotError(
                    f"no {nav.action} server on the graph within {robot_s:g} s; {self.silence()}"
                )
            if len(kinds) != 1:
                raise RobotError(
                    f"the {nav.action} server's result type is {shapes()}: this agent speaks "
                    f"Humble's ({known['humble']}) or Jazzy's ({known['jazzy']})"
                )
            log.info("%s: the server speaks %s's NavigateToPose", nav.action, kinds[0].title())
            return NAV2_DISTROS[kinds[0]]
        if seen and known[nav.distro] not in seen:
            hint = f"set it to {kinds[0]!r} or 'auto'" if len(kinds) == 1 else "see docs/runtime.md"
            raise RobotError(
                f"the {nav.action} server's result type is {shapes()}, not "
                f"{nav.distro.title()}'s ({known[nav.distro]}) that [navigation] distro = "
                f"{nav.distro!r} asks for: {hint}"
            )
        return NAV2_DISTROS[nav.distro]

    def _on_odometry(self, msg: Any) -> None:
        self._set_pose(m.pose_of_odometry(msg), m.stamp_ns(msg.header))

    def _on_tf(self, msg: Any, static: bool = False) -> None:
        frames = self.config.pose
        with self._cond:
            try:
                for parent, child, ns, xyz, q in m.transforms_of(msg):
                    self.tf.add(parent, child, ns, xyz, q, static=static)
            except TransformError as exc:
                raise MessageError(str(exc)) from None
            at = self.tf.latest_common_ns(frames.map_frame, frames.base_frame)
            if at is None:
                return  # not connected yet (or all static): no pose
            try:
                pose = m.pose_of_matrix(self.tf.lookup(frames.map_frame, frames.base_frame, at))
            except TransformError:
                return  # the frames are not connected yet
            self.tf.forget_before(at - TF_CACHE_NS)
        self._set_pose(pose, at)

    def _set_pose(self, pose: Pose, ns: int) -> None:
        with self._cond:
            if ns >= self.pose_ns:
                self.pose, self.pose_ns = pose, ns
            self.pose_count += 1
            self.clock_ns = max(self.clock_ns, ns)
            self.heard_at = time.monotonic()
            self._cond.notify_all()

    def _on_view(self, ns: int, dets: tuple[Detection, ...]) -> None:
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
        #: Nav2 said SUCCEEDED at ``_commanded``: within its tolerance, which is its business.
        self._arrived = False
        self._told_no_tilt = False
        #: Set by a cancelled FindObject goal: the search stops before its next robot command.
        self.cancel = threading.Event()
        self.cancel_reason = ""

    def _check_cancel(self) -> None:
        if self.cancel.is_set():
            raise SearchCancelled(self.cancel_reason or "the search was cancelled")

    def _pose_topic(self) -> str:
        c = self.link.config
        if c.pose.source == "tf":
            return f"{c.topics.tf} ({c.pose.map_frame} → {c.pose.base_frame})"
        return c.topics.odometry

    def wait_for_robot(self, timeout_s: float) -> Pose:
        pose = self.link.wait(lambda: self.link.pose, timeout_s)
        if pose is None:
            raise RobotError(
                f"no pose on {self._pose_topic()} within {timeout_s:g} s: "
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
                f"no fresh pose on {self._pose_topic()} within {timeout_s:g} s; "
                f"{self.link.silence()}"
            )
        self._commanded = None
        self._arrived = False
        return self.pose()

    def pose(self) -> Pose:
        pose = self.link.pose
        if pose is None:
            pose = self.wait_for_robot(self.timeouts.robot_s)
        if self._commanded is not None and (self._arrived or self._at(self._commanded)):
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
        self._check_cancel()
        if self.link.config.navigation.interface == "navigate_to_pose":
            return self._drive_action(self.link.nav2(), goal, view=view)
        goal_stamp = time.time_ns() + next(self._goal_ids)  # unique: the goal's identity
        msg = m.pose_stamped(goal, goal_stamp)
        mark = self.link.mark()
        issued_ns = self.link.clock_ns
        t = self.timeouts
        for _attempt in range(t.attempts):
            self.link.goal_pub.publish(msg)
            # Arrival is a pose at the goal stamped after the clock at sending: the robot's answer
            # to this goal, never a pose it sent before (issue 45: a turn already within tolerance
            # must not return before the robot's answer to it is heard, or the next command's
            # clock would depend on whether that answer had come in yet).
            arrived = self.link.wait(
                lambda: self._at(goal) and self.link.pose_ns > issued_ns and self.link.pose_ns,
                t.arrival_s,
            )
            if not arrived:
                continue
            self._commanded = goal
            if not view:
                return ()
            view_dets = self._view_at(mark, self.link.pose_ns, issued_ns)
            if view_dets is not None:
                return view_dets
        raise RobotError(
            f"the robot did not {'reach' if not view else 'reach and view from'} "
            f"({goal.x:.2f}, {goal.y:.2f}, yaw {goal.yaw:.2f}) after {t.attempts} attempts "
            f"of {t.arrival_s:g} s; {self.link.silence()}"
        )

    def _view_at(self, mark: int, arrival_ns: int, issued_ns: int) -> tuple[Detection, ...] | None:
        """The first view received after ``mark`` and stamped at or after ``arrival_ns`` and after
        ``issued_ns`` (the robot clock when the goal was sent), waiting up to the detections
        timeout; None if none came (an empty view is a view, not None)."""
        after = view_not_before(arrival_ns, issued_ns)
        if not self.link.wait(
            lambda: self.link.view_after(mark, after) is not None, self.timeouts.detections_s
        ):
            return None
        view_dets = self.link.view_after(mark, after)
        assert view_dets is not None
        return view_dets

    def _drive_action(self, nav: ActionClient, goal: Pose, *, view: bool) -> tuple[Detection, ...]:
        t = self.timeouts
        where = f"({goal.x:.2f}, {goal.y:.2f}, yaw {goal.yaw:.2f})"
        what = f"{nav.name} goal to {where}"
        mark = self.link.mark()
        issued_ns = self.link.clock_ns
        self._arrived = False
        for attempt in range(1, t.attempts + 1):
            goal_id = new_goal_id()
            request = m.types()[f"{nav.action}_Goal"](
                pose=m.pose_stamped(goal, self.link.clock_ns),
                behavior_tree=self.link.config.navigation.behavior_tree,
            )
            accepted = nav.send_goal(goal_id, request, t.robot_s)
            if accepted is None:
                why = nav.why_unanswered()  # a server that cannot answer this transport
                raise RobotError(
                    f"no answer to {what} (send_goal) within {t.robot_s:g} s; "
                    + (f"{why}; " if why else "")
                    + self.link.silence()
                )
            if not accepted.accepted:
                raise RobotError(f"the robot rejected the {what}")
            outcome = nav.get_result(goal_id, t.arrival_s)
            if outcome is None:
                # Stuck, or the result was lost: stop that goal before sending another.
                code = nav.cancel(goal_id, t.robot_s)
                log.warning(
                    "%s: no result within %g s (attempt %d); cancel_goal answered %s",
                    what,
                    t.arrival_s,
                    attempt,
                    code,
                )
                continue
            if outcome.status != STATUS_SUCCEEDED:
                # Jazzy's result says why (error_code, error_msg); Humble's is empty.
                code = getattr(outcome.result, "error_code", 0)
                detail = f" (error_code {code}: {outcome.result.error_msg!r})" if code else ""
                raise RobotError(
                    f"the {what} ended {STATUS_NAMES.get(outcome.status, outcome.status)}{detail}"
                )
            self._commanded, self._arrived = goal, True
            if not view:
                return ()
            view_dets = self._view_at(mark, max(accepted.stamp_ns, self.link.clock_ns), issued_ns)
            if view_dets is not None:
                return view_dets
            raise RobotError(
                f"no camera view after the {what} succeeded within {t.detections_s:g} s; "
                f"{self.link.silence()}"
            )
        raise RobotError(
            f"the {what} had no result after {t.attempts} attempts of {t.arrival_s:g} s "
            f"(each cancelled); {self.link.silence()}"
        )

    def navigate(
        self,
        goal: Point,
        *,
        on_detection: DetectionHandler | None = None,
        final_yaw: float | None = None,
    ) -> Navigation:
        return walk_path(
            self.navmap,
            self.pose(),
            goal,
            self._step,
            on_detection=on_detection,
            final_yaw=final_yaw,
        )

    def _step(self, pose: Pose, metres: float, *, view: bool) -> tuple[Detection, ...]:
        return self._drive(pose, view=view)

    def look(self, yaw: float, pitch: float = 0.0) -> tuple[Detection, ...]:
        self._level_camera(pitch)
        here = self.pose()
        return self._drive(Pose(here.x, here.y, yaw), view=True)

    def _level_camera(self, pitch: float) -> None:
        # The robot's interface (a navigation goal, an open service) has no tilt command: its
        # camera stays level whatever the agent asks, which docs/runtime.md states. Said once.
        if pitch != 0.0 and not self._told_no_tilt:
            self._told_no_tilt = True
            log.info(
                "the agent asked for a camera tilt of %.1f° down; this robot has no tilt command, "
                "its views stay level (docs/runtime.md)",
                math.degrees(pitch),
            )

    def open(self, static_id: str, pitch: float = 0.0) -> tuple[Detection, ...]:
        self._level_camera(pitch)
        self._check_cancel()
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
        if not result.ok:
            raise RobotError(f"the robot could not open {static_id!r}: {result.error}")
        stamp = result.stamp_ns
        here = self.pose()
        self._commanded = Pose(here.x, here.y, result.yaw)
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
