"""The geometric search camera (``--camera geometric``): field of view, same room, projected
box area, closed containers — and no occlusion.

A pinhole camera with Kinect-like intrinsics (640×480, 90° horizontal FOV, so f = 320 px) at the
robot's pose. An object is in view when its centre lies within the horizontal FOV and in the robot's
room; its mask area is the projected area of its bounding box (the faces the camera sees, so a
phone lying flat shows its top, not only its 1 cm edge); objects inside a closed container are hidden unless the robot opened that container for this view. Furniture does
not occlude (the paper's simulator reports detections "even far away"; the mask-area threshold is
what limits range). It ignores the camera's pitch (the projected area barely depends on it).
The default search camera is the occluding one (``objsearch.sim.visibility``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from objsearch.agent.geometry import Pose, wrap_angle
from objsearch.agent.home import Box, Home
from objsearch.agent.world import Detection
from objsearch.sim.placements import Placement

IMAGE_WIDTH = 640
IMAGE_HEIGHT = 480


@dataclass(frozen=True, slots=True)
class Camera:
    hfov: float = math.pi / 2
    height: float = 1.0  # metres above the floor
    name: str = "geometric"

    def detections(
        self,
        home: Home,
        room: str,
        pose: Pose,
        pitch: float,
        placed: Sequence[Placement],
        candidates: Sequence[Placement],
        opened: str | None,
    ) -> tuple[Detection, ...]:
        return tuple(
            Detection(p.cls, p.instance_id, self.mask_area(pose, p.box), p.box.center)
            for p in candidates
            if self.in_view(pose, p.box)
        )

    @property
    def focal_px(self) -> float:
        return (IMAGE_WIDTH / 2) / math.tan(self.hfov / 2)

    def in_view(self, pose: Pose, box: Box) -> bool:
        bearing = math.atan2(box.center[1] - pose.y, box.center[0] - pose.x)
        return abs(wrap_angle(bearing - pose.yaw)) <= self.hfov / 2 + 1e-9

    def mask_area(self, pose: Pose, box: Box) -> float:
        """Projected area of the box in pixels: f² / d² times the area of its orthographic
        projection along the line of sight, which for a box is Σ face area × |cos| of the angle
        between the face's normal and the line of sight (the faces turned towards the camera)."""
        dx, dy = box.center[0] - pose.x, box.center[1] - pose.y
        dz = box.center[2] - self.height
        dist = max(math.sqrt(dx * dx + dy * dy + dz * dz), 0.1)
        sx, sy, sz = box.size
        projected = (sy * sz * abs(dx) + sx * sz * abs(dy) + sx * sy * abs(dz)) / dist
        f = self.focal_px
        return min(f * f * projected / (dist * dist), float(IMAGE_WIDTH * IMAGE_HEIGHT))
