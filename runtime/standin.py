"""A stand-in robot: the simulator behind the same ROS 2 topics, types and QoS as a real robot.

It follows goals on ``/goal_pose`` along the viewpoint graph (a goal at its own position turns it
in place and takes a view, as the simulator's ``look``), publishes ``/odom`` (map frame, at
``heartbeat_s`` and after every move) and one ``Detection2DArray`` per camera view, and opens
containers on request. Its clock is the simulator's, carried in every stamp, plus one camera
frame (:data:`FRAME_S`) per teleport between room entries (which the simulator does in no time),
so every view is stamped later than what the robot sent before it. A goal repeated with
the same stamp is answered from the last reply without moving.

Its camera stays level: the robot interface has no tilt command, so the agent's tilt
(``view_taken.pitch``) does not reach it, as on a robot without a tilt unit (docs/runtime.md). It
detects with the default search camera (occluding).

``/objsearch_sim/reset`` ({scene, start}) places the objects of a schedule scene and the robot at
a start, as a simulator's reset service would; a real robot has no such topic.

With ``[navigation] interface = "navigate_to_pose"`` it serves Nav2's action instead of the
goal topic: it accepts each goal, drives it as above (publishing odometry, TF and views), then
finishes it SUCCEEDED; a cancelled goal ends CANCELED. It always publishes /tf (map → odom →
base_link, with a fixed map → odom offset) beside odometry, for ``[pose] source = "tf"``.

Faults for tests: ``drop_every`` drops every n-th outgoing view or odometry message; ``exit_after``
stops answering (the process exits) after that many goals; ``malformed_after`` sends garbage
once after that many goals. Action mode only: the n-th goal is rejected (``reject_after``),
aborted (``abort_after``), never answered (``mute_after``: send_goal gets no reply from then on)
or accepted and never finished (``stall_after``: only a cancel ends it).
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from objsearch.agent.camera_frames import CAMERA_HEIGHT_M, DEFAULT_INTRINSICS, camera_to_map
from objsearch.agent.categories import Category
from objsearch.agent.detector_model import PerceptionModel
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.geometry import Point, Pose, distance
from objsearch.agent.session import Session, load_context
from objsearch.agent.strategies import DEFAULT_STRATEGY, RunSpec
from objsearch.agent.world import Detection
from objsearch.ros.builder import MessageBuilder
from objsearch.ros.detections import MESSAGE_TYPES
from objsearch.ros.topics import TopicMap
from objsearch.ros.types import Distro
from objsearch.runtime import messages as m
from objsearch.runtime.action import STATUS_ABORTED, STATUS_CANCELED, STATUS_SUCCEEDED, ActionServer
from objsearch.runtime.backends import open_transport
from objsearch.runtime.config import RuntimeConfig
from objsearch.runtime.detections_in import CAMERA_INFO
from objsearch.runtime.errors import MessageError
from objsearch.runtime.interfaces import NAV2_DISTROS
from objsearch.runtime.node import Node, Server
from objsearch.runtime.requests import (
    OpenRequest,
    ResetRequest,
    parse_open_request,
    parse_reset_request,
)
from objsearch.sim.detector_model import NoisyDetector
from objsearch.sim.longterm import PAUSE_BETWEEN_TASKS_S
from objsearch.sim.placements import Placements, Schedule, base_placements, table1_removals
from objsearch.sim.schedule_names import load_schedule
from objsearch.sim.world import SimClock, SimWorld

log = logging.getLogger("objsearch.robot")

#: Commands (goals, cancels) waiting for the main loop; more are dropped with a log line.
INBOX_SIZE = 256
#: One frame of a 30 Hz camera: what a teleport between room entries costs in robot time, so
#: each view has a stamp of its own, later than any sent before it, as a camera's frames do.
FRAME_S = 1 / 30


@dataclass(frozen=True, slots=True)
class Faults:
    drop_every: int = 0
    exit_after: int = 0
    malformed_after: int = 0
    reject_after: int = 0
    abort_after: int = 0
    mute_after: int = 0
    stall_after: int = 0


class CameraOut:
    """What a detector node with a level RGB-D camera 1 m up would send (``[detections] input =
    "3d"``): base_link → camera_link → camera_link_optical on /tf at each view's stamp (beside
    map → odom → base_link: over Zenoh a latched /tf_static sent before the agent joined is not
    received), its ``CameraInfo`` and a ``Detection3DArray`` in the optical frame."""

    def __init__(self, config: RuntimeConfig) -> None:
        self.builder = MessageBuilder(Distro.ROS2, TopicMap())
        self.intrinsics = DEFAULT_INTRINSICS

    def frames(self, ns: int) -> Any:
        return self.builder.tf_static(ns, CAMERA_HEIGHT_M, optical=True)

    def info(self, ns: int) -> Any:
        return self.builder.camera_info(ns, self.intrinsics, self.builder.frames.camera_optical)

    def detections(self, ns: int, pose: Pose, dets: Sequence[Detection]) -> Any:
        t_optical_map = np.linalg.inv(camera_to_map(pose, height=CAMERA_HEIGHT_M))
        return self.builder.detections_3d(ns, t_optical_map, self.intrinsics, dets)


class StandInRobot:
    def __init__(
        self,
        config: RuntimeConfig,
        *,
        schedule: str = "table2",
        scene: int | None = None,
        start: str | None = None,
        faults: Faults = Faults(),
        heartbeat_s: float = 0.2,
        perception: PerceptionModel | None = None,
        seed: int = 0,
    ) -> None:
        config.check()
        self.config = config
        self.ctx = load_context(config.home)
        self.schedule = load_schedule(self.ctx.home, schedule)
        self.faults = faults
        self.heartbeat_s = heartbeat_s
        self.clock = SimClock()
        # The modelled detector (docs/perception.md); one for the robot's life, so its views are
        # numbered across resets and a session replays exactly. None: perfect.
        model = perception or PerceptionModel()
        self.detector = (
            None
            if model.perfect
            else NoisyDetector(model, seed, self.ctx.vocabulary.names(Category.SEMI_DYNAMIC))
        )
        if config.detections.input not in ("pose", "3d"):
            raise ObjsearchError(
                f"the stand-in robot publishes [detections] input pose or 3d, "
                f"not {config.detections.input!r}"
            )
        self.camera_out = CameraOut(config) if config.detections.input == "3d" else None
        start_name = start or next(iter(self.ctx.home.starts))
        self.world = self._world(scene, start_name)
        self.node = Node(open_transport(config.transport))
        t, q = config.topics, config.qos
        self._odom = self.node.publisher(t.odometry, m.ODOMETRY, q.odometry)
        self._tf = self.node.publisher(t.tf, m.TF, q.tf)
        self._views = self.node.publisher(
            t.detections, MESSAGE_TYPES[config.detections.input], q.detections
        )
        if self.camera_out is not None:
            self._camera_info = self.node.publisher(t.camera_info, CAMERA_INFO, q.camera)
        # Goals and cancels for the main loop; bounded, so a flood is dropped, not hoarded.
        self._inbox: queue.Queue[tuple[str, Any]] = queue.Queue(maxsize=INBOX_SIZE)
        self.action: ActionServer | None = None
        if config.navigation.interface == "navigate_to_pose":
            # The robot's Nav2: Humble's NavigateToPose unless [navigation] distro says Jazzy.
            nav2 = NAV2_DISTROS["jazzy" if config.navigation.distro == "jazzy" else "humble"]
            self.action = ActionServer(
                self.node,
                config.navigation.action,
                nav2,
                self._on_action_goal,
                lambda goal_id: self._put(("cancel", goal_id)),
                lambda: self.world.now_ns(),
            )
        else:
            self.node.subscribe(t.goal, m.POSE_STAMPED, q.goal, self._on_goal_message)
        self._open = Server(self.node, t.open, t.open_result, q.requests, parse_open_request)
        self._reset = Server(
            self.node, t.sim_reset, t.sim_reset_result, q.requests, parse_reset_request
        )
        self._last_goal: tuple[int, Pose] | None = None
        self._last_views: list[Any] = []
        self._sent = 0
        self.goals = 0
        self._stop = threading.Event()

    def _placements(self, scene: int | None) -> Placements:
        if scene is None:
            return base_placements(self.ctx.home, table1_removals(self.ctx.home))
        if scene not in self.schedule.scenes:
            raise MessageError(f"schedule {self.schedule.name!r} has no scene {scene}")
        return self.schedule.scenes[scene]

    def _world(self, scene: int | None, start: str) -> SimWorld:
        pose = self.ctx.home.start(start)
        return SimWorld(
            self.ctx.home,
            self.ctx.navmap,
            self._placements(scene),
            pose,
            clock=self.clock,
            detector=self.detector,
        )

    # -- output, with dropped messages as a fault ----------------------------------------------

    def _send(self, pub: Any, msg: Any) -> None:
        self._sent += 1
        if self.faults.drop_every and self._sent % self.faults.drop_every == 0:
            log.info("fault: dropping message %d", self._sent)
            return
        pub.publish(msg)

    def _publish_pose(self) -> None:
        pose, ns = self.world.pose(), self.world.now_ns()
        self._send(self._odom, m.odometry(pose, ns))
        self._tf.publish(m.tf(pose, ns))

    def _publish_views(self, views: list[Any]) -> None:
        for view in views:
            if self.camera_out is not None:
                # A camera's frames and calibration at the view's stamp, then its detections.
                ns, pose, dets = view
                self._tf.publish(m.tf(pose, ns))
                self._tf.publish(self.camera_out.frames(ns))
                self._camera_info.publish(self.camera_out.info(ns))
                self._send(self._views, self.camera_out.detections(ns, pose, dets))
            else:
                self._send(self._views, m.detections(*view))

    # -- commands ------------------------------------------------------------------------------

    def _put(self, item: tuple[str, Any]) -> None:
        try:
            self._inbox.put_nowait(item)
        except queue.Full:
            raise MessageError(f"{INBOX_SIZE} commands are waiting; {item[0]} dropped") from None

    def _on_goal_message(self, msg: Any) -> None:
        """On a middleware thread: a goal with a pose that makes no sense is dropped here."""
        self._put(("goal", (m.stamp_ns(msg.header), m.pose_of_pose_stamped(msg))))

    def _on_goal(self, goal_id: int, goal: Pose) -> None:
        if self._last_goal is not None and self._last_goal[0] == goal_id:
            self._publish_pose()
            self._publish_views(self._last_views)
            return
        self.goals += 1
        if self.faults.malformed_after and self.goals == self.faults.malformed_after:
            log.info("fault: sending a malformed detections message")
            self._views._pub.publish(b"\x00\x01\x00\x00garbage")
        self._last_goal = (goal_id, goal)
        views = self._move(goal)
        self._last_views = views
        self._publish_pose()
        self._publish_views(views)

    def _on_action_goal(self, goal_id: bytes, goal: Any) -> bool | None:
        """On a middleware thread: accept (queue for the main loop), reject, or stay silent."""
        f = self.faults
        try:
            pose = m.pose_of_pose_stamped(goal.pose)
        except MessageError as exc:
            log.warning("rejected a navigate_to_pose goal: %s", exc)
            return False
        n = self.goals + 1
        if f.mute_after and n >= f.mute_after:
            log.info("fault: no answer to send_goal %d", n)
            return None
        self.goals = n
        if f.reject_after and n == f.reject_after:
            log.info("fault: rejecting goal %d", n)
            return False
        try:
            self._put(("action", (goal_id, pose, n)))
        except MessageError as exc:
            log.warning("rejected a navigate_to_pose goal: %s", exc)
            return False
        return True

    def _on_action(self, goal_id: bytes, pose: Pose, n: int) -> None:
        assert self.action is not None
        f = self.faults
        if f.stall_after and n == f.stall_after:
            log.info("fault: goal %d accepted and never finished", n)
            self.action.executing(goal_id)
            return
        if f.abort_after and n == f.abort_after:
            log.info("fault: aborting goal %d", n)
            self.action.finish(goal_id, STATUS_ABORTED, self._nav2_result(9000, "fault"))
            return
        self.action.executing(goal_id)
        start = self.world.now_ns()
        self._nav2_feedback(goal_id, pose, start)
        views = self._move(pose)
        self._publish_pose()
        self._publish_views(views)
        self._nav2_feedback(goal_id, pose, start)
        self.action.finish(goal_id, STATUS_SUCCEEDED)

    def _nav2_result(self, code: int, message: str) -> Any:
        """Jazzy's result carries why a goal failed; Humble's is empty."""
        assert self.action is not None
        result = m.default(f"{self.action.action}_Result")
        if hasattr(result, "error_code"):
            result.error_code, result.error_msg = code, message
        return result

    def _nav2_feedback(self, goal_id: bytes, goal: Pose, start_ns: int) -> None:
        """Nav2's feedback: where the robot is, the time so far and the distance left (on the
        viewpoint graph), before each goal's move and at its end."""
        assert self.action is not None
        t = m.types()
        here, now = self.world.pose(), self.world.now_ns()
        target = self._viewpoint(goal)
        path = self.ctx.navmap.path(here.point, target)
        left = sum(distance(path[i], path[i + 1]) for i in range(len(path) - 1))

        def duration(ns: int) -> Any:
            return t["builtin_interfaces/msg/Duration"](sec=ns // 10**9, nanosec=ns % 10**9)

        feedback = t[f"{self.action.action}_Feedback"](
            current_pose=m.pose_stamped(here, now),
            navigation_time=duration(max(0, now - start_ns)),
            estimated_time_remaining=duration(0),
            number_of_recoveries=0,
            distance_remaining=float(left),
        )
        self.action.publish_feedback(goal_id, feedback)

    def _move(self, goal: Pose) -> list[Any]:
        """Drive to ``goal`` along the viewpoint graph; the views taken on the way."""
        here = self.world.pose()
        target = self._viewpoint(goal)
        views: list[Any] = []
        if target == here.point:
            dets = self.world.look(goal.yaw)
            views.append((self.world.now_ns(), self.world.pose(), dets))
        else:
            for b in self.ctx.navmap.path(here.point, target)[1:]:
                before = self.world.now_ns()
                self.world.navigate(b)
                if self.world.now_ns() == before:
                    # A teleport between room entries takes no time; its view is still a new
                    # camera frame, stamped after everything sent before (the agent waits for
                    # such a view: runtime/rosworld.py).
                    self.clock.advance(FRAME_S)
                views.append((self.world.now_ns(), self.world.pose(), self.world.view()))
            if self.world.pose().yaw != goal.yaw:
                self.world.navigate(target, final_yaw=goal.yaw)  # turn in place, no view
        return views

    def _viewpoint(self, goal: Pose) -> Point:
        point = min(
            self.ctx.navmap.room_of, key=lambda p: (p.x - goal.x) ** 2 + (p.y - goal.y) ** 2
        )
        return point

    def _on_open(self, request: OpenRequest) -> dict[str, Any]:
        try:
            dets = self.world.open(request.static_id)
        except ValueError as exc:
            return {"ok": False, "error": f"open request: field 'static_id': {exc}"}
        view = (self.world.now_ns(), self.world.pose(), dets)
        self._last_views = [view]
        self._publish_pose()
        self._publish_views([view])
        return {"ok": True, "stamp_ns": self.world.now_ns(), "yaw": self.world.pose().yaw}

    def _on_reset(self, request: ResetRequest) -> dict[str, Any]:
        try:
            placements = self._placements(request.scene)
        except MessageError as exc:
            return {"ok": False, "error": f"reset request: field 'scene': {exc}"}
        try:
            pose = self.ctx.home.start(request.start)
        except ObjsearchError as exc:
            return {"ok": False, "error": f"reset request: field 'start': {exc}"}
        self.clock.advance(PAUSE_BETWEEN_TASKS_S)
        self.world = SimWorld(
            self.ctx.home,
            self.ctx.navmap,
            placements,
            pose,
            clock=self.clock,
            detector=self.detector,
        )
        self._last_goal = None
        self._publish_pose()
        return {"ok": True, "stamp_ns": self.world.now_ns()}

    # -- main loop -----------------------------------------------------------------------------

    def stop(self) -> None:
        self._stop.set()

    def run(self) -> int:
        """Serve until stopped (or until the ``exit_after`` fault); returns an exit code."""
        try:
            while not self._stop.is_set():
                if self.faults.exit_after and self.goals >= self.faults.exit_after:
                    log.warning("fault: the robot goes away after %d goals", self.goals)
                    return 3
                reset = self._reset.next(0)
                if reset is not None:
                    self._reset.answer(reset, self._on_reset(reset))
                opening = self._open.next(0)
                if opening is not None:
                    self._open.answer(opening, self._on_open(opening))
                try:
                    kind, msg = self._inbox.get(timeout=self.heartbeat_s)
                except queue.Empty:
                    self._publish_pose()
                    continue
                if kind == "goal":
                    self._on_goal(*msg)
                elif kind == "action":
                    self._on_action(*msg)
                elif kind == "cancel" and self.action is not None:
                    self.action.finish(msg, STATUS_CANCELED)
        finally:
            self.node.close()
        return 0


def in_process_search(log_dir: Path, scene: int, target: str, start: str) -> dict[str, Any]:
    """One search of Table II's ``scene`` in the in-process simulator on a fresh log: what the
    agent behind a stand-in must answer for it (``runtime.requestfuzz`` checks this)."""
    ctx = load_context("paper")
    placements = Schedule.load(ctx.home, "table2").scenes[scene]
    session = Session.start(
        ctx, log_dir, RunSpec.of(ctx.home.name, ctx.home.digest, DEFAULT_STRATEGY)
    )
    try:
        world = SimWorld(ctx.home, ctx.navmap, placements, ctx.home.start(start), clock=SimClock())
        r = session.search(world, target, start, scene=scene)
    finally:
        session.close()
    plans = [[room, list(order)] for room, order in r.plans]
    return {
        "success": r.success,
        "path_length": r.path_length,
        "found": r.found_instance,
        "plans": plans,
        "task_id": r.task_id,
    }
