"""RGB-D frames as a robot's camera delivers them, and the geometry that turns pixels into points.

A frame is what the semantic-map builder and the detectors consume, whatever produced it: the
simulator's renderer (``objsearch.sim.render``) or, later, a ROS bag's image, depth, camera info
and TF. Conventions: depth in metres along the optical axis, 0 where the sensor has no return;
the camera's optical frame is x right, y down, z forward (REP-103's ``*_optical_frame``), and
``T_map_camera`` is the 4×4 transform from that frame to the ``map`` frame.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from functools import lru_cache
from typing import Protocol

import numpy as np
import numpy.typing as npt

from objsearch.agent.geometry import Pose

FloatArray = npt.NDArray[np.float32]
Float64Array = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True, slots=True)
class CameraIntrinsics:
    """A pinhole camera (no distortion), as in a ``sensor_msgs/CameraInfo``'s K matrix."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def from_hfov(cls, width: int, height: int, hfov: float) -> CameraIntrinsics:
        """Square pixels, principal point at the image centre, horizontal field of view in rad."""
        f = (width / 2) / math.tan(hfov / 2)
        return cls(width, height, f, f, (width - 1) / 2, (height - 1) / 2)

    @property
    def shape(self) -> tuple[int, int]:
        return (self.height, self.width)

    def rays(self) -> FloatArray:
        """(H, W, 3) ray per pixel centre in the optical frame, scaled so that z = 1 (so a ray
        times the pixel's depth is the point)."""
        return _rays(self)


@lru_cache(maxsize=8)
def _rays(k: CameraIntrinsics) -> FloatArray:
    u = (np.arange(k.width, dtype=np.float32) - np.float32(k.cx)) / np.float32(k.fx)
    v = (np.arange(k.height, dtype=np.float32) - np.float32(k.cy)) / np.float32(k.fy)
    rays = np.empty((k.height, k.width, 3), dtype=np.float32)
    rays[..., 0] = u[None, :]
    rays[..., 1] = v[:, None]
    rays[..., 2] = 1.0
    rays.setflags(write=False)
    return rays


#: The simulated Kinect-like camera: 640×480 with the 90° horizontal field of view the mask-area
#: thresholds of ``data/vocabulary.json`` were derived for (f = 320 px), 1 m above the floor.
DEFAULT_INTRINSICS = CameraIntrinsics.from_hfov(640, 480, math.pi / 2)
CAMERA_HEIGHT_M = 1.0
#: The tilt unit's range, as AI2-THOR's ``horizon``: level (0) to 60° down. Up is never needed:
#: with a 74° vertical field of view a level camera at 1 m already sees 1.4 m high at 1 m.
MAX_PITCH = math.radians(60.0)


def pitch_towards(
    here: tuple[float, float],
    target: tuple[float, float, float],
    *,
    height: float = CAMERA_HEIGHT_M,
) -> float:
    """The camera pitch (radians down) that puts ``target`` on the optical axis when the robot
    stands at ``here`` facing it, clamped to the tilt unit's range [0, MAX_PITCH]."""
    horizontal = max(math.hypot(target[0] - here[0], target[1] - here[1]), 1e-6)
    return min(max(math.atan2(height - target[2], horizontal), 0.0), MAX_PITCH)


def camera_to_map(
    pose: Pose, *, height: float = CAMERA_HEIGHT_M, pitch: float = 0.0
) -> Float64Array:
    """T_map_camera for a camera at ``height`` above the robot's pose, looking along its yaw and
    tilted down by ``pitch`` radians."""
    cy, sy = math.cos(pose.yaw), math.sin(pose.yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    t = np.eye(4)
    t[:3, 0] = (sy, -cy, 0.0)  # optical x: right of the heading
    t[:3, 1] = (-cy * sp, -sy * sp, -cp)  # optical y: down
    t[:3, 2] = (cy * cp, sy * cp, -sp)  # optical z: forward
    t[:3, 3] = (pose.x, pose.y, height)
    return t


@dataclass(frozen=True, slots=True, eq=False)
class GroundTruth:
    """What a simulator knows of every pixel (never present on a robot): the index of the object
    seen there (-1: nothing of note) and each index's instance id and class."""

    instance: npt.NDArray[np.int32]  # (H, W)
    ids: tuple[str, ...]
    classes: tuple[str, ...]


@dataclass(frozen=True, slots=True, eq=False)
class RGBDFrame:
    rgb: npt.NDArray[np.uint8]  # (H, W, 3)
    depth: FloatArray  # (H, W) metres, 0 = no return
    intrinsics: CameraIntrinsics
    T_map_camera: Float64Array  # (4, 4)
    stamp_ns: int = 0
    truth: GroundTruth | None = None

    def __post_init__(self) -> None:
        shape = self.intrinsics.shape
        if self.depth.shape != shape or self.rgb.shape != (*shape, 3):
            raise ValueError(
                f"frame images {self.rgb.shape} / {self.depth.shape} do not match the camera's "
                f"{self.intrinsics.width}×{self.intrinsics.height}"
            )
        if self.T_map_camera.shape != (4, 4):
            raise ValueError(f"T_map_camera must be 4×4, not {self.T_map_camera.shape}")

    @property
    def position(self) -> tuple[float, float, float]:
        x, y, z = (float(v) for v in self.T_map_camera[:3, 3])
        return (x, y, z)


class FrameSource(Protocol):
    """Anything that yields frames in capture order: the simulator's survey, a bag reader."""

    def frames(self) -> Iterator[RGBDFrame]: ...


def backproject(frame: RGBDFrame, mask: BoolArray | None = None) -> FloatArray:
    """(N, 3) map-frame points of the pixels in ``mask`` (all pixels if None) that have depth."""
    valid = frame.depth > 0
    if mask is not None:
        valid &= mask
    cam = frame.intrinsics.rays()[valid] * frame.depth[valid][:, None]
    rot = frame.T_map_camera[:3, :3].astype(np.float32)
    trans = frame.T_map_camera[:3, 3].astype(np.float32)
    out = cam @ rot.T + trans
    return out.astype(np.float32, copy=False)


def project(
    points: FloatArray, intrinsics: CameraIntrinsics, T_map_camera: Float64Array
) -> tuple[FloatArray, FloatArray]:
    """Map-frame points to (N, 2) pixel coordinates (u, v) and their (N,) depths."""
    inv = np.linalg.inv(T_map_camera)
    cam = points.astype(np.float64) @ inv[:3, :3].T + inv[:3, 3]
    z = cam[:, 2]
    uv = np.stack(
        (
            intrinsics.fx * cam[:, 0] / z + intrinsics.cx,
            intrinsics.fy * cam[:, 1] / z + intrinsics.cy,
        ),
        axis=1,
    )
    return uv.astype(np.float32), z.astype(np.float32)
