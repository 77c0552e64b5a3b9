"""Axis-aligned boxes in the ROS frame, and the per-room Unity -> ROS conversion with offset."""

from __future__ import annotations

import math
from dataclasses import dataclass

from objsearch.agent.geometry import Vec3

from .coordinate_frames import (
    unity_floor_to_ros,
    unity_size_to_ros,
    unity_to_ros,
    unity_yaw_to_ros,
)


@dataclass(frozen=True)
class Box:
    """An axis-aligned bounding box: ``center`` and full ``size`` per axis, ROS frame."""

    center: Vec3
    size: Vec3

    @property
    def lo(self) -> Vec3:
        c, s = self.center, self.size
        return (c[0] - s[0] / 2, c[1] - s[1] / 2, c[2] - s[2] / 2)

    @property
    def hi(self) -> Vec3:
        c, s = self.center, self.size
        return (c[0] + s[0] / 2, c[1] + s[1] / 2, c[2] + s[2] / 2)

    def distance_to(self, point: Vec3) -> float:
        """Euclidean distance from ``point`` to the box; 0 inside it."""
        gaps = (
            max(abs(p - c) - s / 2, 0.0)
            for p, c, s in zip(point, self.center, self.size, strict=True)
        )
        return math.sqrt(sum(g * g for g in gaps))

    def footprint_contains(self, x: float, y: float) -> bool:
        lo, hi = self.lo, self.hi
        return lo[0] <= x <= hi[0] and lo[1] <= y <= hi[1]


def distance(a: Vec3, b: Vec3) -> float:
    return math.dist(a, b)


@dataclass(frozen=True)
class RoomFrame:
    """Unity -> ROS conversion followed by the room's translation on the home map."""

    dx: float = 0.0
    dy: float = 0.0

    def point(self, unity: Vec3) -> Vec3:
        x, y, z = unity_to_ros(unity)
        return (x + self.dx, y + self.dy, z)

    def floor_point(self, unity_x: float, unity_z: float) -> tuple[float, float]:
        x, y = unity_floor_to_ros(unity_x, unity_z)
        return (x + self.dx, y + self.dy)

    def box(self, unity_center: Vec3, unity_size: Vec3) -> Box:
        return Box(self.point(unity_center), unity_size_to_ros(unity_size))

    @staticmethod
    def yaw(unity_yaw_deg: float) -> float:
        return unity_yaw_to_ros(unity_yaw_deg)
