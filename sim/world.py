"""A simulated home the agent can search: motion on the viewpoint graph, a camera, containers."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from objsearch.agent.camera_frames import pitch_towards
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.geometry import Point, Pose, distance, heading
from objsearch.agent.home import Home
from objsearch.agent.navigation import walk_path
from objsearch.agent.navmap import NavigationMap
from objsearch.agent.world import Detection, DetectionHandler, Navigation
from objsearch.sim.perception import Camera
from objsearch.sim.placements import Placement
from objsearch.sim.visibility import OccludingCamera

if TYPE_CHECKING:
    from objsearch.agent.strategies import RunSpec
    from objsearch.sim.detector_model import NoisyDetector
    from objsearch.sim.localisation import Localiser

SPEED_M_PER_S = 0.5
LOOK_S = 1.0
OPEN_S = 3.0
REACH_M = 1.5  # a container can be opened from this close


class SearchCamera(Protocol):
    """What a search's camera reports from one pose: detections of the ``candidates`` (objects
    placed in ``room`` that are not shut in a closed container), with ``placed`` (every object
    placed in the room) and the room's statics as what may stand in the way, ``opened`` (a
    container the robot opened for this view) taken out of the room."""

    @property
    def name(self) -> str: ...

    def detections(
        self,
        home: Home,
        room: str,
        pose: Pose,
        pitch: float,
        placed: Sequence[Placement],
        candidates: Sequence[Placement],
        opened: str | None,
    ) -> tuple[Detection, ...]: ...


#: Search cameras by name (``--camera``); the first is the default.
CAMERAS = ("occluding", "geometric")
DEFAULT_CAMERA = CAMERAS[0]


def search_camera(name: str = DEFAULT_CAMERA) -> SearchCamera:
    """The search camera called ``name``: ``occluding`` (what a render of the room shows) or
    ``geometric`` (field of view and projected area, furniture does not occlude)."""
    if name == "occluding":
        return OccludingCamera()
    if name == "geometric":
        return Camera()
    raise ObjsearchError(f"unknown search camera {name!r}; choose from {', '.join(CAMERAS)}")


def with_camera(spec: RunSpec) -> tuple[RunSpec, SearchCamera]:
    """The spec's search camera (``params["camera"]``), and the spec with it recorded: a spec that
    names none gets the default, so every simulated log says which camera produced it."""
    name = spec.params.get("camera", DEFAULT_CAMERA)
    camera = search_camera(str(name))
    return spec.with_changes(params={**spec.params, "camera": camera.name}), camera


#: The two directions of one shortest path may sum their steps in another order: ways this close
#: count as equal (m).
ROUNDING_M = 1e-6


def facing_view(viewpoint: Point, target: tuple[float, float, float]) -> tuple[Pose, float]:
    """The pose and camera pitch of a robot at ``viewpoint`` looking straight at ``target``."""
    return (
        Pose(viewpoint.x, viewpoint.y, heading(viewpoint, Point(target[0], target[1]))),
        pitch_towards((viewpoint.x, viewpoint.y), target),
    )


def mask_facing(
    camera: SearchCamera,
    home: Home,
    viewpoint: Point,
    target: Placement,
    placed: Sequence[Placement],
) -> float:
    """The target's mask area (px) from ``viewpoint``, facing it with the camera pitched at it
    and, if it lies in a container, with that container opened; ``placed`` is everything placed
    in its room (the target included)."""
    pose, pitch = facing_view(viewpoint, target.box.center)
    opened = target.support if target.inside else None
    seen = camera.detections(home, target.room, pose, pitch, placed, (target,), opened)
    return seen[0].mask_area if seen else 0.0


@dataclass(frozen=True, slots=True)
class FirstSighting:
    """The first viewpoint (of those tried, in their order) that detects a placement, and the
    mask it shows there; when none does, ``viewpoint`` is None and ``mask_px`` the largest mask
    any of them showed."""

    viewpoint: Point | None
    mask_px: float


def first_sighting(
    camera: SearchCamera,
    home: Home,
    target: Placement,
    placed: Sequence[Placement],
    viewpoints: Iterable[Point],
    min_mask_px: float,
) -> FirstSighting:
    """Try ``viewpoints`` in order, facing ``target`` (:func:`mask_facing`), until one shows at
    least ``min_mask_px`` of it: the one walk over a room's viewpoints that the oracle, the
    seeable-placement check and the bench's failure causes share."""
    largest = 0.0
    for v in viewpoints:
        area = mask_facing(camera, home, v, target, placed)
        if area >= min_mask_px:
            return FirstSighting(v, area)
        largest = max(largest, area)
    return FirstSighting(None, largest)


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
        camera: SearchCamera | None = None,
        observer: WorldObserver | None = None,
        detector: NoisyDetector | None = None,
        localiser: Localiser | None = None,
    ) -> None:
        self.home = home
        self.navmap = navmap
        self.placements = dict(placements)
        self._placed: dict[str, tuple[Placement, ...]] = {}
        self.clock = clock or SimClock()
        self.camera = camera or search_camera()
        #: The modelled detector the camera's detections pass through (None: a perfect one);
        #: the oracle measures with the camera alone.
        self.detector = detector
        #: The robot's pose error (None: it knows where it is). The pose the agent reads and the
        #: graph the robot moves on are the *believed* ones; the camera sees from the true pose.
        self.localiser = localiser
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

    def _view(
        self, pose: Pose, pitch: float = 0.0, opened: str | None = None
    ) -> tuple[Detection, ...]:
        room = self.navmap.room_at(pose.x, pose.y)
        placed = self._in_room(room)
        candidates = [p for p in placed if not p.inside or p.support == opened]
        loc = self.localiser
        at = pose if loc is None else loc.true_pose(pose)
        seen = self.camera.detections(self.home, room, at, pitch, placed, candidates, opened)
        if self.detector is not None:
            seen = self.detector.observe(self.home, room, at, placed, seen)
        if loc is not None:
            # Placed from where the robot believes it stands: off by its pose error.
            seen = tuple(
                dataclasses.replace(d, position=loc.reconstruct(d.position, pose)) for d in seen
            )
        if self.observer is not None:
            self.observer.camera_frame(self.clock.ns, pose, seen)
        return seen

    def _in_room(self, room: str) -> tuple[Placement, ...]:
        # Asked at every step: the placements are fixed for the world's life.
        if room not in self._placed:
            self._placed[room] = tuple(
                sorted(
                    (p for p in self.placements.values() if p.room == room),
                    key=lambda p: p.instance_id,
                )
            )
        return self._placed[room]

    def is_instance_of(self, instance_id: str | None, cls: str) -> bool:
        """Whether ``instance_id`` is a placed ``cls`` object: a search's "found" is a success
        only then (a modelled detector's false positive or confusion is not)."""
        placed = self.placements.get(instance_id) if instance_id is not None else None
        return placed is not None and placed.cls == cls

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

    def true_pose(self) -> Pose:
        """Where the robot is (the simulator's truth; the agent reads :meth:`pose`)."""
        return self._pose if self.localiser is None else self.localiser.true_pose(self._pose)

    def _step(self, pose: Pose, metres: float, *, view: bool) -> tuple[Detection, ...]:
        self.clock.advance(metres / SPEED_M_PER_S)
        if self.localiser is not None:
            self.localiser.advance(metres)
        self._set_pose(pose)
        return self._view(pose) if view else ()

    def oracle_length(self, cls: str, *, min_mask_px: float) -> float:
        """The full path of a robot that knew where a ``cls`` object is — the limit for any
        search strategy, measured like a search's full path: the walk from here to the nearest
        viewpoint from which it is detectable (mask ≥ ``min_mask_px`` facing it, camera pitched
        at it, its container opened), then on to the viewpoint nearest the object, where a
        search's approach ends. When no viewpoint detects one, the walk to that viewpoint."""
        targets = [p for p in self.placements.values() if p.cls == cls]
        if not targets:
            raise ValueError(f"no {cls} is placed in this world")
        here = self._pose.point

        def here_to(v: Point) -> float:
            return self.navmap.distance(here, v)

        approach = {
            p.instance_id: self.navmap.nearest_viewpoint(p.box.center[0], p.box.center[1], p.room)
            for p in targets
        }
        best = math.inf
        for p in targets:
            a = approach[p.instance_id]
            # Each viewpoint by its whole way (walk there, then on to the approach; the second
            # leg measured from the approach's side: one shortest-path tree instead of one per
            # viewpoint, equal up to rounding), nearer the object first among equal ways, so
            # the first detecting viewpoint is the answer: a room has hundreds of viewpoints and
            # each look-up renders the room.
            ways = sorted(
                (
                    round(here_to(v) + self.navmap.distance(a, v), 6),
                    math.dist((v.x, v.y), p.box.center[:2]),
                    v,
                )
                for v in self.navmap.viewpoints(p.room)
            )
            shorter = [v for way, _, v in ways if way < best - ROUNDING_M]
            seen = first_sighting(
                self.camera, self.home, p, self._in_room(p.room), shorter, min_mask_px
            )
            if seen.viewpoint is not None:
                # Measured as a search walks it: from here to the viewpoint, then to the approach.
                best = min(best, here_to(seen.viewpoint) + self.navmap.distance(seen.viewpoint, a))
        if best < math.inf:
            return best
        return min(self.navmap.distance(here, n) for n in approach.values())

    def look(self, yaw: float, pitch: float = 0.0) -> tuple[Detection, ...]:
        self.clock.advance(LOOK_S)
        self._set_pose(Pose(self._pose.x, self._pose.y, yaw))
        return self._view(self._pose, pitch)

    def open(self, static_id: str, pitch: float = 0.0) -> tuple[Detection, ...]:
        container = self._statics.get(static_id)
        if container is None or not container.container:
            raise ValueError(f"{static_id!r} is not a container of home {self.home.name!r}")
        target = Point(container.box.center[0], container.box.center[1])
        if distance(self._pose, target) - max(container.box.size[:2]) / 2 > REACH_M:
            raise ValueError(f"robot at {self._pose} is too far to open {static_id!r}")
        self.clock.advance(OPEN_S)
        self._set_pose(Pose(self._pose.x, self._pose.y, heading(self._pose, target)))
        return self._view(self._pose, pitch, opened=static_id)
