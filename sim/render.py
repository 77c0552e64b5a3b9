"""RGB, depth and instance masks of a simulated room, ray-cast from its boxes (numpy, vectorised).

A room is its shell — the floor, four walls and a ceiling on the room's extent, seen from inside —
and the axis-aligned boxes of its static objects and of the semi-dynamic objects placed in it.
Each pixel's ray is intersected with the shell and, within the box's projected rectangle only, with
every box (the slab method); the nearest hit gives depth (along the optical axis, as a depth camera
reports it), instance and a flat-shaded colour. Boxes are what the home data gives (see
docs/perception.md for what that means for L-shaped counters and shelving units).
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from objsearch.agent.camera_frames import (
    CAMERA_HEIGHT_M,
    DEFAULT_INTRINSICS,
    CameraIntrinsics,
    Float64Array,
    FloatArray,
    GroundTruth,
    RGBDFrame,
    camera_to_map,
)
from objsearch.agent.geometry import Pose
from objsearch.agent.home import Box, Home, Room
from objsearch.sim.world import Placement

WALL_HEIGHT_M = 2.5
MAX_RANGE_M = 10.0  # beyond this the simulated sensor reports no return (depth 0)
NEAR_M = 0.05

#: Instance values of pixels that show no object (``GroundTruth.instance``).
NO_RETURN, FLOOR, WALL, CEILING = -1, -2, -3, -4

_SHADE = np.array([0.78, 0.9, 1.0], dtype=np.float32)  # faces normal to x, y, z
_SHELL_RGB = {FLOOR: (150, 140, 120), WALL: (225, 225, 215), CEILING: (245, 245, 245)}


@dataclass(frozen=True, slots=True)
class SceneObject:
    id: str
    cls: str
    box: Box


@dataclass(frozen=True, slots=True)
class Scene:
    """One room's geometry: its shell (an axis-aligned box, seen from inside) and its objects."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    objects: tuple[SceneObject, ...]

    def without(self, object_id: str) -> Scene:
        """The scene with one object taken out (an opened container shows what it holds)."""
        return Scene(self.lo, self.hi, tuple(o for o in self.objects if o.id != object_id))


def room_scene(home: Home, room: str | Room, placements: Iterable[Placement] = ()) -> Scene:
    """A room's statics plus the placements that lie in it, in a shell on the room's extent."""
    r = home.room(room) if isinstance(room, str) else room
    pts = [(v.x, v.y) for v in r.viewpoints]
    lo_x = min([p[0] for p in pts] + [s.box.center[0] - s.box.size[0] / 2 for s in r.statics])
    hi_x = max([p[0] for p in pts] + [s.box.center[0] + s.box.size[0] / 2 for s in r.statics])
    lo_y = min([p[1] for p in pts] + [s.box.center[1] - s.box.size[1] / 2 for s in r.statics])
    hi_y = max([p[1] for p in pts] + [s.box.center[1] + s.box.size[1] / 2 for s in r.statics])
    margin = home.grid  # viewpoints stand at least a grid step off the walls
    objects = [SceneObject(s.id, s.cls, s.box) for s in r.statics]
    objects += [
        SceneObject(p.instance_id, p.cls, p.box)
        for p in sorted(placements, key=lambda p: p.instance_id)
        if p.room == r.name
    ]
    return Scene(
        (lo_x - margin, lo_y - margin, 0.0),
        (hi_x + margin, hi_y + margin, WALL_HEIGHT_M),
        tuple(objects),
    )


def class_colour(cls: str) -> tuple[int, int, int]:
    """A fixed colour per class (the same in every run and on every machine)."""
    digest = hashlib.sha256(cls.encode()).digest()
    return (64 + digest[0] % 160, 64 + digest[1] % 160, 64 + digest[2] % 160)


@dataclass(frozen=True, slots=True, eq=False)
class Rendered:
    rgb: npt.NDArray[np.uint8]
    depth: FloatArray
    instance: npt.NDArray[np.int32]


def render(
    scene: Scene,
    intrinsics: CameraIntrinsics,
    T_map_camera: Float64Array,
    *,
    max_range: float = MAX_RANGE_M,
) -> Rendered:
    rays = intrinsics.rays()
    rot = T_map_camera[:3, :3].astype(np.float32)
    origin = T_map_camera[:3, 3].astype(np.float32)
    # Planar (3, H, W) map-frame directions; t along them is depth. Per-axis planes keep every
    # reduction below an element-wise min/max of three contiguous images.
    d = np.ascontiguousarray(np.moveaxis(rays @ rot.T, 2, 0))
    with np.errstate(divide="ignore"):
        inv = np.float32(1.0) / d
    # The shell: the ray leaves the room box at t_far; the axis it leaves by names the surface.
    exits = []
    for a in range(3):
        with np.errstate(invalid="ignore"):
            exits.append(
                np.maximum((scene.lo[a] - origin[a]) * inv[a], (scene.hi[a] - origin[a]) * inv[a])
            )
    depth = np.minimum(np.minimum(exits[0], exits[1]), exits[2])
    axis = np.where(exits[2] == depth, 2, np.where(exits[1] == depth, 1, 0)).astype(np.int8)
    instance = np.where(axis == 2, np.where(d[2] < 0, FLOOR, CEILING), WALL).astype(np.int32)

    inv_t: Float64Array = np.linalg.inv(T_map_camera).astype(np.float64)
    for k, obj in enumerate(scene.objects):
        window = _window(obj.box, inv_t, intrinsics)
        if window is None:
            continue
        r0, r1, c0, c1 = window
        near: list[FloatArray] = []
        t_far: FloatArray | None = None
        for a in range(3):
            lo_a = obj.box.center[a] - obj.box.size[a] / 2
            inv_a = inv[a, r0:r1, c0:c1]
            with np.errstate(invalid="ignore"):
                t1 = (np.float32(lo_a) - origin[a]) * inv_a
                t2 = (np.float32(lo_a + obj.box.size[a]) - origin[a]) * inv_a
                near.append(np.minimum(t1, t2))
                far_a = np.maximum(t1, t2)
            t_far = far_a if t_far is None else np.minimum(t_far, far_a)
        assert t_far is not None
        t_near = np.maximum(np.maximum(near[0], near[1]), near[2])
        current = depth[r0:r1, c0:c1]
        # A ray parallel to a slab it starts outside of gives nan there, which compares False.
        hit = (t_near <= t_far) & (t_near > NEAR_M) & (t_near < current)
        if not hit.any():
            continue
        current[hit] = t_near[hit]
        instance[r0:r1, c0:c1][hit] = k
        face = np.where(near[2] == t_near, 2, np.where(near[1] == t_near, 1, 0)).astype(np.int8)
        axis[r0:r1, c0:c1][hit] = face[hit]
    far = ~(depth <= max_range)
    depth[far] = 0.0
    instance[far] = NO_RETURN
    rgb = _colours(scene, instance, axis)
    return Rendered(rgb, depth.astype(np.float32, copy=False), instance)


def _window(box: Box, inv_t: Float64Array, k: CameraIntrinsics) -> tuple[int, int, int, int] | None:
    """The pixel rectangle the box can cover: its corners' projections, or the whole image when
    the box reaches behind the camera; None when it is wholly behind or outside the image."""
    c = np.asarray(box.center)
    s = np.asarray(box.size) / 2
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    corners = c + signs * s
    cam = corners @ inv_t[:3, :3].T + inv_t[:3, 3]
    z = cam[:, 2]
    if (z <= NEAR_M).all():
        return None
    if (z <= NEAR_M).any():
        return (0, k.height, 0, k.width)
    u = k.fx * cam[:, 0] / z + k.cx
    v = k.fy * cam[:, 1] / z + k.cy
    c0, c1 = max(int(np.floor(u.min())), 0), min(int(np.ceil(u.max())) + 1, k.width)
    r0, r1 = max(int(np.floor(v.min())), 0), min(int(np.ceil(v.max())) + 1, k.height)
    if c0 >= c1 or r0 >= r1:
        return None
    return (r0, r1, c0, c1)


def _colours(
    scene: Scene, instance: npt.NDArray[np.int32], axis: npt.NDArray[np.int8]
) -> npt.NDArray[np.uint8]:
    n = len(scene.objects)
    # Lookup table indexed by instance + 4 (shell codes are -4…-1).
    table = np.zeros((n + 4, 3), dtype=np.float32)
    for code, colour in _SHELL_RGB.items():
        table[code + 4] = colour
    for k, obj in enumerate(scene.objects):
        table[k + 4] = class_colour(obj.cls)
    shaded = (table[None] * _SHADE[:, None, None]).astype(np.uint8)  # (3 faces, n + 4, 3)
    out: npt.NDArray[np.uint8] = shaded[axis, instance + 4]
    return out


class SimulatedCamera:
    """The simulator's RGB-D camera: renders frames, with ground truth, at robot poses."""

    def __init__(
        self,
        home: Home,
        placements: Mapping[str, Placement] | Sequence[Placement] = (),
        *,
        intrinsics: CameraIntrinsics = DEFAULT_INTRINSICS,
        height: float = CAMERA_HEIGHT_M,
        pitch: float = 0.0,
    ) -> None:
        self.home = home
        items = placements.values() if isinstance(placements, Mapping) else placements
        self.placements = tuple(items)
        self.intrinsics = intrinsics
        self.height = height
        self.pitch = pitch
        self._scenes: dict[str, Scene] = {}

    def scene(self, room: str) -> Scene:
        if room not in self._scenes:
            self._scenes[room] = room_scene(self.home, room, self.placements)
        return self._scenes[room]

    def frame(
        self, pose: Pose, room: str, *, stamp_ns: int = 0, opened: str | None = None
    ) -> RGBDFrame:
        scene = self.scene(room)
        if opened is not None:
            scene = scene.without(opened)
        t = camera_to_map(pose, height=self.height, pitch=self.pitch)
        out = render(scene, self.intrinsics, t)
        truth = GroundTruth(
            out.instance,
            tuple(o.id for o in scene.objects),
            tuple(o.cls for o in scene.objects),
        )
        return RGBDFrame(out.rgb, out.depth, self.intrinsics, t, stamp_ns, truth)


@dataclass(frozen=True)
class SurveyFrames:
    """A :class:`~objsearch.agent.camera_frames.FrameSource` over a survey's poses, rendered lazily."""

    camera: SimulatedCamera
    poses: tuple[tuple[str, Pose], ...]  # (room, pose)

    def frames(self) -> Iterator[RGBDFrame]:
        for i, (room, pose) in enumerate(self.poses):
            yield self.camera.frame(pose, room, stamp_ns=i * 1_000_000_000)
