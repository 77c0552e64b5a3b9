"""A map's frame, and re-anchoring the robot's reports in a new map to the frame of its memory.

A fresh SLAM map has its own frame: its origin and heading are wherever the mapping started, so
the same kitchen table has other coordinates in ``map-1`` than in ``map-0``. The agent's
navigation and semantic maps and every position its log holds are in one frame, the *working*
frame (the frame of the map its home was first given). When a session starts in a new map whose
world says where that map puts the statics (:class:`ReportsStatics`), the agent *registers* the
new map to the working frame: it matches statics by id and class across the two maps and fits
the rigid transform (rotation about z and translation, least squares, :func:`register`), then
reads every pose and detection the robot reports through it (:class:`InFrame`), so nothing in
the new map's coordinates is mixed with the old map's. A world that reports no statics (a robot
without a rebuilt semantic map) is taken to be in the working frame, as before.

Matching by id is how the simulator's new map names its statics (it keeps the home's ids); a real
system would first match statics by class and geometry (e.g. the pairwise distances between
same-class objects). Two matched statics fix a rigid transform in the plane; more are averaged.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from objsearch.agent.errors import ObjsearchError
from objsearch.agent.geometry import Point, Pose, Vec3
from objsearch.agent.navmap import NavigationMap
from objsearch.agent.semmap import SemanticMap
from objsearch.agent.world import Detection, DetectionHandler, Navigation, World

#: A registration whose matched statics lie further apart than this (RMS, metres) after the fit
#: is refused: the two maps do not describe the same statics.
MAX_REGISTRATION_RMS_M = 0.25


@dataclass(frozen=True, slots=True)
class Rigid2D:
    """A rigid transform of the floor plane: rotate by ``yaw`` about z, then translate by
    (``x``, ``y``). Heights are unchanged."""

    yaw: float = 0.0
    x: float = 0.0
    y: float = 0.0

    def point(self, px: float, py: float) -> tuple[float, float]:
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return (c * px - s * py + self.x, s * px + c * py + self.y)

    def pose(self, pose: Pose) -> Pose:
        x, y = self.point(pose.x, pose.y)
        return Pose(x, y, pose.yaw + self.yaw)

    def position(self, v: Vec3) -> Vec3:
        x, y = self.point(v[0], v[1])
        return (x, y, v[2])

    def inverse(self) -> Rigid2D:
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return Rigid2D(-self.yaw, -(c * self.x + s * self.y), -(-s * self.x + c * self.y))

    def params(self) -> dict[str, float]:
        return {"yaw": self.yaw, "x": self.x, "y": self.y}


@dataclass(frozen=True, slots=True)
class Registration:
    """A new map registered to the working frame: ``to_working`` maps the new map's coordinates
    into it; ``matched`` statics were paired; ``rms_m`` is their residual after the fit."""

    to_working: Rigid2D
    matched: int
    rms_m: float

    def params(self) -> dict[str, float]:
        return {**self.to_working.params(), "matched": self.matched, "rms_m": self.rms_m}


@runtime_checkable
class ReportsStatics(World, Protocol):
    """A world whose map says where it puts each static: id → (class, position on the floor)."""

    def mapped_statics(self) -> Mapping[str, tuple[str, Point]]: ...


def register(working: SemanticMap, new: Mapping[str, tuple[str, Point]]) -> Registration:
    """Fit the rigid transform taking ``new`` (a new map's statics) onto ``working`` (the
    semantic map the agent's memory is anchored to), pairing statics with the same id and class
    (2-D Kabsch: centroids, then the rotation that best aligns the centred points)."""
    pairs = [
        (s.box.center[0], s.box.center[1], new[s.id][1])
        for s in working.statics
        if s.id in new and new[s.id][0] == s.cls
    ]
    if len(pairs) < 2:
        raise ObjsearchError(
            f"cannot register the new map: {len(pairs)} of its statics match the old map's "
            "(at least 2 are needed)"
        )
    n = len(pairs)
    ax = sum(p[2].x for p in pairs) / n
    ay = sum(p[2].y for p in pairs) / n
    bx = sum(p[0] for p in pairs) / n
    by = sum(p[1] for p in pairs) / n
    dot = cross = 0.0
    for wx, wy, q in pairs:
        ux, uy, vx, vy = q.x - ax, q.y - ay, wx - bx, wy - by
        dot += ux * vx + uy * vy
        cross += ux * vy - uy * vx
    yaw = math.atan2(cross, dot)
    c, s = math.cos(yaw), math.sin(yaw)
    fit = Rigid2D(yaw, bx - (c * ax - s * ay), by - (s * ax + c * ay))
    rms = math.sqrt(sum(math.dist(fit.point(q.x, q.y), (wx, wy)) ** 2 for wx, wy, q in pairs) / n)
    if rms > MAX_REGISTRATION_RMS_M:
        raise ObjsearchError(
            f"cannot register the new map: its {n} matched statics lie {rms:.2f} m (RMS) from "
            f"the old map's after the best rigid fit (at most {MAX_REGISTRATION_RMS_M} m)"
        )
    return Registration(fit, n, rms)


class InFrame:
    """``world`` as seen in another frame: every pose, route and detection it reports is mapped
    by ``transform``, every goal and heading the caller gives is mapped back. A point that lands
    on a viewpoint of ``outer`` (the caller's navigation map) to a micrometre is that viewpoint,
    and a goal mapped back is snapped onto ``inner`` (the world's): the graphs' points stay
    exact."""

    def __init__(
        self,
        world: World,
        transform: Rigid2D,
        *,
        inner: NavigationMap | None = None,
        outer: NavigationMap | None = None,
    ) -> None:
        self.world = world
        self.transform = transform
        self._back = transform.inverse()
        self._inner = inner
        self._outer = outer

    def _out(self, p: Point) -> Point:
        return _on(self._outer, *self.transform.point(p.x, p.y))

    def _out_pose(self, pose: Pose) -> Pose:
        p = self._out(Point(pose.x, pose.y))
        return Pose(p.x, p.y, pose.yaw + self.transform.yaw)

    def _detections(self, seen: tuple[Detection, ...]) -> tuple[Detection, ...]:
        return tuple(_moved(d, self.transform.position(d.position)) for d in seen)

    def pose(self) -> Pose:
        return self._out_pose(self.world.pose())

    def now_ns(self) -> int:
        return self.world.now_ns()

    def navigate(
        self,
        goal: Point,
        *,
        on_detection: DetectionHandler | None = None,
        final_yaw: float | None = None,
    ) -> Navigation:
        handler = None
        if on_detection is not None:
            outer_handler = on_detection

            def handler(d: Detection, pose: Pose) -> bool:
                moved = _moved(d, self.transform.position(d.position))
                return outer_handler(moved, self._out_pose(pose))

        inner_goal = _on(self._inner, *self._back.point(goal.x, goal.y))
        nav = self.world.navigate(
            inner_goal,
            on_detection=handler,
            final_yaw=None if final_yaw is None else final_yaw - self.transform.yaw,
        )
        return Navigation(
            tuple(self._out(p) for p in nav.path),
            nav.metres,
            self._out_pose(nav.end),
            nav.rooms,
            nav.interrupted,
        )

    def look(self, yaw: float, pitch: float = 0.0) -> tuple[Detection, ...]:
        return self._detections(self.world.look(yaw - self.transform.yaw, pitch))

    def open(self, static_id: str, pitch: float = 0.0) -> tuple[Detection, ...]:
        return self._detections(self.world.open(static_id, pitch))


def _moved(d: Detection, position: Vec3) -> Detection:
    return dataclasses.replace(d, position=position)


def _on(navmap: NavigationMap | None, x: float, y: float) -> Point:
    """(x, y), or the viewpoint of ``navmap`` it stands on to a micrometre (viewpoints are
    stored rounded to 4 decimals)."""
    if navmap is not None:
        snapped = Point(round(x, 4), round(y, 4))
        if snapped in navmap.room_of and math.hypot(snapped.x - x, snapped.y - y) < 1e-6:
            return snapped
    return Point(x, y)
