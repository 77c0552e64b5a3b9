"""A simulated home the agent can search: motion on the viewpoint graph, a camera, containers."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

from objsearch.agent.geometry import Point, Pose, distance, heading
from objsearch.agent.home import Box, Home
from objsearch.agent.navigation import walk_path
from objsearch.agent.navmap import NavigationMap
from objsearch.agent.world import Detection, DetectionHandler, Navigation
from objsearch.sim.perception import Camera

SPEED_M_PER_S = 0.5
LOOK_S = 1.0
OPEN_S = 3.0
REACH_M = 1.5  # a container can be opened from this close


@dataclass(frozen=True, slots=True)
class Placement:
    """Where one semi-dynamic object is for one task."""

    instance_id: str
    cls: str
    box: Box
    room: str
    support: str | None
    inside: bool


class WorldObserver(Protocol):
    """Sees what the robot's sensors would publish: every pose change and every camera frame.

    ``objsearch record`` turns these into odometry, TF and detection messages; the agent never
    sees an observer.
    """

    def pose_changed(self, time_ns: int, pose: Pose) -> None: ...

    def camera_frame(self, time_ns: int, pose: Pose, detections: Sequence[Detection]) -> None: ...


class SimClock:
    """Simulated time, shared by successive tasks so a log's clock never runs backwards."""

    def __init__(self, start_ns: int = 0) -> None:
        self.ns = start_ns

    def advance(self, seconds: float) -> None:
        self.ns += round(seconds * 1e9)


class SimWorld:
    """Implements :class:`objsearch.agent.world.World` from home data."""

    def __init__(
        self,
        home: Home,
        navmap: NavigationMap,
        placements: Mapping[str, Placement],
        start: Pose,
        *,
        clock: SimClock | None = None,
        camera: Camera | None = None,
        observer: WorldObserver | None = None,
    ) -> None:
        self.home = home
        self.navmap = navmap
        self.placements = dict(placements)
        self.clock = clock or SimClock()
        self.camera = camera or Camera()
        self._statics = home.statics
        self._pose = start
        self.observer = observer
        if start.point not in navmap.room_of:
            raise ValueError(f"start {start} is not a viewpoint of home {home.name!r}")
        self._set_pose(start)

    def pose(self) -> Pose:
        return self._pose

    def now_ns(self) -> int:
        return self.clock.ns

    def _set_pose(self, pose: Pose) -> None:
        self._pose = pose
        if self.observer is not None:
            self.observer.pose_changed(self.clock.ns, pose)

    def _view(self, pose: Pose, opened: str | None = None) -> tuple[Detection, ...]:
        room = self.navmap.room_at(pose.x, pose.y)
        seen = []
        for p in sorted(self.placements.values(), key=lambda p: p.instance_id):
            if p.room != room or not self.camera.in_view(pose, p.box):
                continue
            if p.inside and p.support != opened:
                continue
            seen.append(
                Detection(p.cls, p.instance_id, self.camera.mask_area(pose, p.box), p.box.center)
            )
        if self.observer is not None:
            self.observer.camera_frame(self.clock.ns, pose, seen)
        return tuple(seen)

    def view(self) -> tuple[Detection, ...]:
        """What the camera sees from where the robot stands, without turning or spending time."""
        return self._view(self._pose)

    def navigate(
        self,
        goal: Point,
        *,
        on_detection: DetectionHandler | None = None,
        final_yaw: float | None = None,
    ) -> Navigation:
        return walk_path(
            self.navmap,
            self._pose,
            goal,
            self._step,
            on_detection=on_detection,
            final_yaw=final_yaw,
        )

    def _step(self, pose: Pose, metres: float, *, view: bool) -> tuple[Detection, ...]:
        self.clock.advance(metres / SPEED_M_PER_S)
        self._set_pose(pose)
        return self._view(pose) if view else ()

    def oracle_length(self, cls: str) -> float:
        """Shortest walk from here to the nearest viewpoint of the closest ``cls`` object: the
        path length of a robot that knew where it was (the limit for any search strategy)."""
        lengths = [
            self.navmap.distance(
                self._pose.point,
                self.navmap.nearest_viewpoint(p.box.center[0], p.box.center[1], p.room),
            )
            for p in self.placements.values()
            if p.cls == cls
        ]
        if not lengths:
            raise ValueError(f"no {cls} is placed in this world")
        return min(lengths)

    def look(self, yaw: float) -> tuple[Detection, ...]:
        self.clock.advance(LOOK_S)
        self._set_pose(Pose(self._pose.x, self._pose.y, yaw))
        return self._view(self._pose)

    def open(self, static_id: str) -> tuple[Detection, ...]:
        container = self._statics.get(static_id)
        if container is None or not container.container:
            raise ValueError(f"{static_id!r} is not a container of home {self.home.name!r}")
        target = Point(container.box.center[0], container.box.center[1])
        if distance(self._pose, target) - max(container.box.size[:2]) / 2 > REACH_M:
            raise ValueError(f"robot at {self._pose} is too far to open {static_id!r}")
        self.clock.advance(OPEN_S)
        self._set_pose(Pose(self._pose.x, self._pose.y, heading(self._pose, target)))
        return self._view(self._pose, opened=static_id)
