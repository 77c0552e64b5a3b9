"""The per-room Unity -> ROS conversion with offset, giving the agent's boxes (``agent.home.Box``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from objsearch.agent.geometry import Vec3
from objsearch.agent.home import Box

from .coordinate_frames import (
    unity_floor_to_ros,
    unity_size_to_ros,
    unity_to_ros,
    unity_yaw_to_ros,
)


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
