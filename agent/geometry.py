"""Poses and points in the project's canonical REP-103 ``map`` frame (metres, radians)."""

from __future__ import annotations

import math
from typing import NamedTuple

#: Three coordinates (x, y, z): a point in space or a box's size, in whichever frame the caller
#: says (the ``map`` frame unless named otherwise). The project's one 3-vector type.
Vec3 = tuple[float, float, float]


class Point(NamedTuple):
    """A position on the floor."""

    x: float
    y: float


class Pose(NamedTuple):
    """A robot pose on the floor: position and yaw (counter-clockwise from +x)."""

    x: float
    y: float
    yaw: float

    @property
    def point(self) -> Point:
        return Point(self.x, self.y)

    def as_dict(self) -> dict[str, float]:
        return {"x": round(self.x, 4), "y": round(self.y, 4), "yaw": round(self.yaw, 4)}


def wrap_angle(angle: float) -> float:
    """Wrap an angle to (-pi, pi]."""
    wrapped = math.remainder(angle, math.tau)
    return math.pi if wrapped == -math.pi else wrapped


def heading(src: Point | Pose, dst: Point | Pose) -> float:
    """Yaw that faces ``dst`` from ``src`` (0 when they coincide)."""
    dx, dy = dst[0] - src[0], dst[1] - src[1]
    if dx == 0 and dy == 0:
        return 0.0
    return math.atan2(dy, dx)


def distance(a: Point | Pose, b: Point | Pose) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1])
