"""A recorded robot session replayed to the agent: the bag's camera views, read by the one
converter the live agent uses (:mod:`objsearch.ros.detections`), and the robot's poses, served
to a fresh agent as a :class:`~objsearch.agent.world.World` (:class:`RecordedRobot`), which
searches again for what the recorded agent was asked (its ``task_started`` events, read from the
bag's ``/objsearch/events`` by :func:`~objsearch.pipeline.bags.read.read_bag`).

Which view answers which robot command is the live agent's rule (``runtime/rosworld.py``), the
one function :func:`~objsearch.ros.detections.view_not_before`: the command's arrival is the
first recorded pose within tolerance of its goal stamped after the robot's clock when it was
given (the newest stamp the agent had heard: the arrival or view of the command before); its
view is the first recorded view stamped at or after arrival and after that clock. An open request's view is the first stamped after the
clock. A replay that asks for a pose the robot never reached, or a view that was never recorded,
has diverged from the recording: :class:`ReplayDiverged` says at which command.
"""

from __future__ import annotations

import bisect
import math
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from objsearch.agent.camera_frames import CameraIntrinsics
from objsearch.agent.catalogue import STORE, RunStarted, TaskStarted, decode
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.geometry import Point, Pose, wrap_angle
from objsearch.agent.navigation import walk_path
from objsearch.agent.navmap import NavigationMap
from objsearch.agent.session import Session, load_context
from objsearch.agent.strategies import RunSpec
from objsearch.agent.world import Detection, DetectionHandler, Navigation
from objsearch.events import Event, read_log
from objsearch.pipeline.bags.errors import BagError
from objsearch.pipeline.bags.formats import detect
from objsearch.pipeline.bags.read import read_bag
from objsearch.pipeline.bags.readers import read_messages
from objsearch.pipeline.bags.salvage import RawConnection
from objsearch.pipeline.bags.sink import Deserialize
from objsearch.ros import detections as conv
from objsearch.ros.errors import TransformError
from objsearch.ros.images import depth_metres, intrinsics_of
from objsearch.ros.tf import TransformBuffer
from objsearch.ros.topics import Role, TopicMap
from objsearch.ros.untrusted import attempt

#: What the live agent takes as arrival (runtime/config.py Timeouts' defaults).
TOLERANCE_M = 0.05
TOLERANCE_RAD = 0.05
DETECTION_TYPES = frozenset(conv.MESSAGE_TYPES.values())


class ReplayDiverged(ObjsearchError):
    """The replayed agent asked for something the recording does not hold."""


@dataclass
class RecordedViews:
    """A :class:`~objsearch.pipeline.bags.sink.MessageSink` collecting a session's odometry
    (map frame) and detection arrays, TF, camera info and depth images; :meth:`views` converts
    the arrays once everything is read."""

    topic_map: TopicMap
    input: str = "pose"
    tf: TransformBuffer = field(default_factory=TransformBuffer)
    conns: dict[int, tuple[RawConnection, Role]] = field(default_factory=dict)
    others: dict[int, RawConnection] = field(default_factory=dict)
    counts: Counter[str] = field(default_factory=Counter)
    poses: list[tuple[int, int, Pose]] = field(default_factory=list)  # (stamp, arrival, pose)
    arrays: list[tuple[int, int, Any]] = field(default_factory=list)  # (stamp, arrival, msg)
    cameras: list[tuple[int, str, CameraIntrinsics]] = field(default_factory=list)
    depths: dict[int, tuple[str, Any]] = field(default_factory=dict)
    rejected: Counter[str] = field(default_factory=Counter)

    def plan(
        self, conns: Iterable[RawConnection], known: Callable[[RawConnection], str | None]
    ) -> None:
        wanted = {
            Role.ODOMETRY: {"nav_msgs/msg/Odometry"},
            Role.TF: {"tf2_msgs/msg/TFMessage"},
            Role.TF_STATIC: {"tf2_msgs/msg/TFMessage"},
            Role.CAMERA_INFO: {"sensor_msgs/msg/CameraInfo"},
            Role.DEPTH: {"sensor_msgs/msg/Image"},
            Role.DETECTIONS: {conv.MESSAGE_TYPES[self.input]},
        }
        for c in conns:
            role = self.topic_map.role(c.topic)
            if role in wanted and c.msgtype in wanted[role] and known(c) is None:
                self.conns[c.id] = (c, role)
            elif c.id not in self.conns:
                self.others[c.id] = c

    def wants(self, conn_id: int) -> bool:
        return conn_id in self.conns

    def count(self, conn_id: int, n: int = 1) -> None:
        entry = self.conns.get(conn_id)
        conn = entry[0] if entry is not None else self.others.get(conn_id)
        if conn is not None:
            self.counts[conn.topic] += n

    def messages_per_topic(self) -> Counter[str]:
        return Counter(self.counts)

    def end_of_messages(self) -> None:
        pass

    def feed(self, conn_id: int, log_ns: int, raw: bytes, deserialize: Deserialize) -> None:
        entry = self.conns.get(conn_id)
        if entry is None:
            self.count(conn_id)
            return
        conn, role = entry
        self.counts[conn.topic] += 1
        arrival = sum(self.counts.values())
        taken = attempt(lambda: self._take(role, deserialize(raw, conn.msgtype), arrival))
        if isinstance(taken, Exception):
            self.rejected[f"{conn.topic}: {type(taken).__name__}: {taken}"[:200]] += 1

    def _take(self, role: Role, msg: Any, arrival: int) -> None:
        if role in (Role.TF, Role.TF_STATIC):
            for tr in msg.transforms:
                t, q = tr.transform.translation, tr.transform.rotation
                self.tf.add(
                    conv.frame_of(tr.header),
                    str(tr.child_frame_id).lstrip("/"),
                    conv.stamp_ns(tr.header),
                    np.array([t.x, t.y, t.z], dtype=np.float64),
                    np.array([q.x, q.y, q.z, q.w], dtype=np.float64),
                    static=role is Role.TF_STATIC,
                )
            return
        stamp = conv.stamp_ns(msg.header)
        if role is Role.ODOMETRY:
            if conv.frame_of(msg.header) != self.topic_map.frames.map:
                raise ValueError(f"odometry in {msg.header.frame_id!r}, not the map frame")
            p, q = msg.pose.pose.position, msg.pose.pose.orientation
            yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
            self.poses.append((stamp, arrival, Pose(float(p.x), float(p.y), yaw)))
        elif role is Role.DETECTIONS:
            self.arrays.append((stamp, arrival, msg))
        elif role is Role.CAMERA_INFO:
            intr, _ = intrinsics_of(msg)
            self.cameras.append((stamp, conv.frame_of(msg.header), intr))
        elif role is Role.DEPTH:
            self.depths[stamp] = (conv.frame_of(msg.header), depth_metres(msg))

    def views(self) -> list[tuple[int, tuple[Detection, ...]]]:
        """Every detection array that can be placed, as (stamp, detections), in stamp order
        (then arrival); the others are counted in :attr:`rejected` with why."""
        out = []
        for stamp, _, msg in sorted(self.arrays, key=lambda a: (a[0], a[1])):
            try:
                out.append((stamp, self._convert(stamp, msg)))
            except (conv.DetectionError, TransformError, ValueError) as exc:
                self.rejected[f"detections stamped {stamp}: {exc}"[:200]] += 1
        return out

    def _transform(self, frame: str, stamp: int) -> Any:
        target = self.topic_map.frames.map
        return np.eye(4) if frame == target else self.tf.lookup(target, frame, stamp)

    def _camera(self, stamp: int) -> tuple[str, CameraIntrinsics]:
        earlier = [c for c in self.cameras if c[0] <= stamp]
        if not earlier:
            raise ValueError("no camera info at or before it")
        _, frame, intr = max(earlier, key=lambda c: c[0])
        return frame, intr

    def _convert(self, stamp: int, msg: Any) -> tuple[Detection, ...]:
        frame = conv.frame_of(msg.header)
        if self.input == "pose":
            return conv.from_pose_2d(msg, self._transform(frame, stamp))
        cam_frame, camera = self._camera(stamp)
        if self.input == "3d":
            t_map = self._transform(frame, stamp)
            t_cam = np.linalg.inv(self._transform(cam_frame, stamp)) @ t_map
            return conv.from_3d(msg, t_map, camera, t_cam)
        if stamp not in self.depths:
            raise ValueError("no depth image of its stamp")
        depth_frame, depth = self.depths[stamp]
        dets, _ = conv.from_depth_2d(msg, depth, camera, self._transform(depth_frame, stamp))
        return tuple(dets)


@dataclass(frozen=True, slots=True)
class Recording:
    """A bag's session: the agent's own events and what its robot sent."""

    agent: tuple[Event, ...]
    poses: tuple[tuple[int, Pose], ...]  # stamp order
    views: tuple[tuple[int, tuple[Detection, ...]], ...]  # stamp order
    rejected: dict[str, int]


def read_recording(
    path: Path, topic_map: TopicMap | None = None, *, input: str = "pose"
) -> Recording:
    """The agent's events (read by the ingest pipeline, checksums checked) and the robot's
    poses and views (each array through the one converter) of the bag at ``path``."""
    topic_map = topic_map or TopicMap()
    contents = read_bag(path, topic_map)
    sink, _ = read_messages(path, detect(path), lambda: RecordedViews(topic_map, input))
    views = sink.views()
    if not contents.agent:
        raise BagError(f"{path}: no agent events (objsearch_msgs/Event) to replay")
    if not views:
        raise BagError(
            f"{path}: no camera views could be read ({conv.MESSAGE_TYPES[input]}"
            + (f"; {dict(sink.rejected)}" if sink.rejected else "")
            + ")"
        )
    poses = tuple((s, p) for s, _, p in sorted(sink.poses, key=lambda x: (x[0], x[1])))
    return Recording(contents.agent, poses, tuple(views), dict(sink.rejected))


class RecordedRobot:
    """The robot of a recording, as a :class:`~objsearch.agent.world.World` (module docstring)."""

    def __init__(self, navmap: NavigationMap, recording: Recording, start_ns: int) -> None:
        self.navmap = navmap
        self.poses = recording.poses
        self._pose_stamps = [s for s, _ in self.poses]
        self.views = recording.views
        self._view_stamps = [s for s, _ in self.views]
        self.commands = 0
        #: The newest robot stamp the agent has heard: what its next command is given after.
        self.clock = start_ns
        before = bisect.bisect_right(self._pose_stamps, start_ns)
        if before == 0:
            raise ReplayDiverged(f"no recorded pose at or before the task's start ({start_ns})")
        self._pose = self._snap(self.poses[before - 1][1])

    def _snap(self, pose: Pose) -> Pose:
        point = min(self.navmap.room_of, key=lambda p: (p.x - pose.x) ** 2 + (p.y - pose.y) ** 2)
        if math.hypot(point.x - pose.x, point.y - pose.y) <= TOLERANCE_M:
            return Pose(point.x, point.y, pose.yaw)
        return pose

    def pose(self) -> Pose:
        return self._pose

    def now_ns(self) -> int:
        return self.clock

    def _arrive(self, goal: Pose) -> int:
        self.commands += 1
        # Stamped after the clock, as live (runtime/rosworld.py): the robot's answer to this
        # command, never a pose sent before it.
        i = bisect.bisect_right(self._pose_stamps, self.clock)
        for stamp, p in self.poses[i:]:
            if (
                math.hypot(p.x - goal.x, p.y - goal.y) <= TOLERANCE_M
                and abs(wrap_angle(p.yaw - goal.yaw)) <= TOLERANCE_RAD
            ):
                return stamp
        raise ReplayDiverged(
            f"command {self.commands}: the recorded robot never reached ({goal.x:.2f}, "
            f"{goal.y:.2f}, yaw {goal.yaw:.2f}) stamped after {self.clock}"
        )

    def _view(self, at: int, what: str) -> tuple[Detection, ...]:
        """The first view stamped at or after ``at`` (of one stamp, the first recorded)."""
        j = bisect.bisect_left(self._view_stamps, at)
        if j >= len(self.views):
            raise ReplayDiverged(
                f"command {self.commands} ({what}): no recorded view stamped at or after {at}"
            )
        self.clock = max(self.clock, self.views[j][0])
        return self.views[j][1]

    def _step(self, pose: Pose, metres: float, *, view: bool) -> tuple[Detection, ...]:
        issued = self.clock
        arrived = self._arrive(pose)
        self._pose = pose
        self.clock = max(self.clock, arrived)
        if view:
            return self._view(conv.view_not_before(arrived, issued), "view")
        return ()

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

    def look(self, yaw: float, pitch: float = 0.0) -> tuple[Detection, ...]:
        here = self.pose()
        return self._step(Pose(here.x, here.y, yaw), 0.0, view=True)

    def open(self, static_id: str, pitch: float = 0.0) -> tuple[Detection, ...]:
        self.commands += 1
        dets = self._view(conv.view_not_before(self.clock, self.clock), f"open {static_id}")
        # The robot turned to the container: its pose at the view.
        i = bisect.bisect_left(self._pose_stamps, self.clock)
        if i < len(self.poses):
            here = self.pose()
            self._pose = Pose(here.x, here.y, self.poses[i][1].yaw)
        return dets


@dataclass(frozen=True, slots=True)
class Replay:
    """The recorded agent's events and the replayed one's, for :func:`decisions`."""

    recorded: tuple[Event, ...]
    replayed: tuple[Event, ...]
    tasks: int


def replay_recording(
    recording: Recording,
    home: str,
    log_dir: Path,
    progress: Callable[[list[Event]], Iterable[Event]] = iter,
) -> Replay:
    """A fresh agent with the recorded run's spec, on a new log at ``log_dir``, searches again
    for each recorded task on :class:`RecordedRobot` (``progress`` wraps the tasks' starts)."""
    ctx = load_context(home)
    runs = [decode(e, RunStarted) for e in recording.agent if e.type == "run_started"]
    if len(runs) != 1:
        raise BagError(f"the recording holds {len(runs)} runs; one is replayed at a time")
    spec = RunSpec.from_record(runs[0])
    session = Session.start(ctx, log_dir, spec)
    tasks = [e for e in recording.agent if e.type == "task_started"]
    try:
        for e in progress(tasks):
            started = decode(e, TaskStarted)
            world = RecordedRobot(ctx.navmap, recording, e.time_ns)
            session.search(
                world, started.target, started.start, scene=started.scene, clock=started.clock
            )
    finally:
        session.close()
    replayed = tuple(read_log(log_dir, store=STORE))
    return Replay(recording.agent, replayed, len(tasks))


#: The fields of an event that say what the agent decided (not when, or under which ids).
def decisions(events: Sequence[Event]) -> list[tuple[str, int, str | None, Any]]:
    """(type, version, task, payload) of every event but the run's bookkeeping: what the agent
    saw, planned, confirmed, rejected and concluded, comparable across two runs."""
    skip = {"run_started", "prior_loaded"}
    return [
        (e.type, e.version, e.task_id, e.payload)
        for e in events
        if e.type not in skip and not e.type.startswith("log_")
    ]


def first_difference(
    recorded: Sequence[tuple[str, int, str | None, Any]],
    replayed: Sequence[tuple[str, int, str | None, Any]],
) -> int | None:
    """The index of the first decision that differs (one list ending early differs there), or
    None when the two are the same."""
    for i, (a, b) in enumerate(zip(recorded, replayed, strict=False)):
        if a != b:
            return i
    return None if len(recorded) == len(replayed) else min(len(recorded), len(replayed))
