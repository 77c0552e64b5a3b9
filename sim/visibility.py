"""The occluding search camera: what a full render of the room would show of each object, cheaply.

An object's mask area is the number of pixels its instance covers in ``render(room_scene(...))``
— room shell, every static box, every placed object, an opened container taken out — but only
the object's own projected window is ray-cast, and only against the boxes whose windows overlap
it. A pixel belongs to the object exactly when it does in the full render: the same float32
directions (``render.inverse_directions``), the same slab test (``render.slab``), the same boxes
cut away (``render.support_cutouts``), the same rule for ties (the render paints objects in scene
order and a later one wins only when strictly nearer) and the same range limit. Results are cached
per view (see :class:`VisibilityCache`), so the same pose in another search, scene or strategy
costs a dictionary look-up; the rays of a camera rotation seen before are not turned again
(:class:`DirectionCache`), and an object well inside the room's shell is not tested against it.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cache

import numpy as np

from objsearch.agent.camera_frames import (
    CAMERA_HEIGHT_M,
    DEFAULT_INTRINSICS,
    CameraIntrinsics,
    Float64Array,
    FloatArray,
    camera_to_map,
)
from objsearch.agent.geometry import Pose
from objsearch.agent.home import Box, Home
from objsearch.agent.world import Detection
from objsearch.sim.placements import Placement
from objsearch.sim.render import (
    MAX_RANGE_M,
    Scene,
    Window,
    corner_windows,
    intersect,
    inverse_directions,
    room_scene,
    shell_depth,
    slab,
    support_cutouts,
)

#: Float32 rays meet a box a few µm off its true depth: a box is skipped as an occluder only when
#: its nearest corner is this much farther than the candidate's farthest.
DEPTH_MARGIN_M = 1e-3
#: Views kept in memory: one entry is a few ids and floats; 200k views is a few tens of MB and
#: more than a whole ``bench paper`` visits.
CACHE_VIEWS = 200_000
#: Placed-object sequences whose key part is remembered (a few per world; worlds are short-lived).
PLACED_KEYS = 64
#: Whole-image inverse ray directions kept, one per camera rotation (3.7 MB each at 640 × 480).
#: A search walks in a few headings: on a ``bench homes`` run 8 rotations carry 85 % of the
#: ray-cast pixels and 32 carry 94 %.
DIRECTION_IMAGES = 32
#: Rotations remembered as seen once (a key each): a rotation's whole image is computed only
#: when it comes back, so a look at a pose never repeated costs only its windows.
SEEN_ROTATIONS = 4096
#: A box at least this far inside the room's shell on every side cannot be hidden by it from a
#: camera inside the shell: the shell's exit lies beyond the box on every ray, by far more than
#: float32 rounding (1e-5 m at 10 m), so the test against the shell is skipped.
INSIDE_SHELL_M = 0.01


class DirectionCache:
    """Inverse ray directions (:func:`render.inverse_directions`) of whole images, by camera
    rotation and intrinsics, least recently used first out. Element-wise arithmetic makes a
    window cut from the whole image the same, bit for bit, as the window computed alone."""

    def __init__(self, max_images: int = DIRECTION_IMAGES) -> None:
        self.max_images = max_images
        self._images: OrderedDict[tuple[CameraIntrinsics, bytes], FloatArray] = OrderedDict()
        self._seen: OrderedDict[tuple[CameraIntrinsics, bytes], None] = OrderedDict()

    def window(self, k: CameraIntrinsics, rot: FloatArray, win: Window) -> FloatArray:
        r0, r1, c0, c1 = win
        key = (k, rot.tobytes())
        image = self._images.get(key)
        if image is not None:
            self._images.move_to_end(key)
            return image[:, r0:r1, c0:c1]
        if key not in self._seen:
            self._seen[key] = None
            if len(self._seen) > SEEN_ROTATIONS:
                self._seen.popitem(last=False)
            return inverse_directions(k.rays()[r0:r1, c0:c1], rot)
        image = self._images[key] = inverse_directions(k.rays(), rot)
        if len(self._images) > self.max_images:
            self._images.popitem(last=False)
        return image[:, r0:r1, c0:c1]


#: Shared by every occluding camera of a process (the rotations recur in every search).
SHARED_DIRECTIONS = DirectionCache()


def _inside_shell(scene: Scene, box: Box, origin: FloatArray) -> bool:
    """Whether the shell can hide no part of ``box`` from ``origin`` (see INSIDE_SHELL_M)."""
    for a in range(3):
        lo, hi = scene.lo[a] + INSIDE_SHELL_M, scene.hi[a] - INSIDE_SHELL_M
        half = box.size[a] / 2
        if not (lo <= box.center[a] - half and box.center[a] + half <= hi):
            return False
        if not (scene.lo[a] < float(origin[a]) < scene.hi[a]):
            return False
    return True


def mask_areas(
    scene: Scene,
    candidates: Sequence[str],
    T_map_camera: Float64Array,
    intrinsics: CameraIntrinsics = DEFAULT_INTRINSICS,
    *,
    max_range: float = MAX_RANGE_M,
    directions: DirectionCache = SHARED_DIRECTIONS,
) -> dict[str, int]:
    """Pixels of each candidate (an object id of ``scene``) in a render of ``scene`` from
    ``T_map_camera``; 0 for a candidate the render would not show."""
    rot = T_map_camera[:3, :3].astype(np.float32)
    origin = T_map_camera[:3, 3].astype(np.float32)
    inv_t: Float64Array = np.linalg.inv(T_map_camera).astype(np.float64)
    index = scene.index
    boxes = corner_windows(scene.corners, inv_t, intrinsics)
    windows = boxes.rects
    if all(windows[index[c]] is None for c in candidates):
        return dict.fromkeys(candidates, 0)  # 2 in 5 computed views of a bench run show none
    out: dict[str, int] = {}
    for object_id in candidates:
        k = index[object_id]
        win = windows[k]
        if win is None:
            out[object_id] = 0
            continue
        r0, _, c0, _ = win
        inv = directions.window(intrinsics, rot, win)
        _, t_k, own = slab(scene.objects[k].box, origin, inv)
        own &= t_k <= max_range
        if not _inside_shell(scene, scene.objects[k].box, origin):
            shell, _ = shell_depth(scene, origin, inv)
            own &= t_k < shell
        rows, cols = np.flatnonzero(own.any(axis=1)), np.flatnonzero(own.any(axis=0))
        if rows.size == 0:
            out[object_id] = 0
            continue
        # Only the pixels the candidate covers can be hidden, and only by a box in front of it.
        seen = (
            r0 + int(rows[0]),
            r0 + int(rows[-1]) + 1,
            c0 + int(cols[0]),
            c0 + int(cols[-1]) + 1,
        )
        farthest = boxes.far[k] + DEPTH_MARGIN_M
        occluders = [
            (j, overlap)
            for j in range(len(scene.objects))
            if j != k
            and boxes.near[j] <= farthest
            and (overlap := intersect(seen, windows[j])) is not None
        ]
        ids = {object_id} | {scene.objects[j].id for j, _ in occluders}
        cutouts = support_cutouts(scene, windows, origin, inv, win, ids)
        if object_id in cutouts:
            own &= ~cutouts[object_id]
        for j, (a0, a1, b0, b1) in occluders:
            other = scene.objects[j]
            sub = (slice(a0 - r0, a1 - r0), slice(b0 - c0, b1 - c0))
            _, t_j, hit = slab(other.box, origin, inv[:, sub[0], sub[1]])
            if other.id in cutouts:
                hit &= ~cutouts[other.id][sub]
            # The render paints in scene order: an earlier object keeps a pixel on a tie.
            nearer = t_j <= t_k[sub] if j < k else t_j < t_k[sub]
            own[sub] &= ~(hit & nearer)
        out[object_id] = int(own.sum())
    return out


ViewKey = tuple[object, ...]


class _Placed:
    """The placed objects of a view key, hashed once (a search asks for thousands of views of
    one room with the same objects in it)."""

    __slots__ = ("_hash", "items")

    def __init__(self, items: tuple[Placement, ...]) -> None:
        self.items = items
        self._hash = hash(items)

    def __hash__(self) -> int:
        return self._hash

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Placed) and self.items == other.items


#: One key object per distinct placed-object sequence: every world builds its own tuples, and a
#: cache look-up whose key holds the same object compares by identity instead of comparing every
#: placement field by field (which took most of a cache hit's time).
_INTERNED: dict[_Placed, _Placed] = {}
INTERNED_KEYS = 4096


def _intern(key: _Placed) -> _Placed:
    if len(_INTERNED) >= INTERNED_KEYS:
        _INTERNED.clear()  # only slower look-ups for the keys already cached, never wrong ones
    return _INTERNED.setdefault(key, key)


class VisibilityCache:
    """Mask areas by view, least recently used first out when full.

    A view is the home (its digest), the room, the camera pose (x, y, yaw, pitch to 1e-6), the
    opened container and the objects placed in that room (id, box, support): everything the
    render of the room depends on (the statics are fixed per home)."""

    def __init__(self, max_views: int = CACHE_VIEWS) -> None:
        self.max_views = max_views
        self._views: OrderedDict[ViewKey, dict[str, int]] = OrderedDict()
        self.hits = 0
        self.misses = 0

    def get(self, key: ViewKey) -> dict[str, int] | None:
        found = self._views.get(key)
        if found is None:
            self.misses += 1
            return None
        self.hits += 1
        self._views.move_to_end(key)
        return found

    def put(self, key: ViewKey, areas: dict[str, int]) -> None:
        self._views[key] = areas
        if len(self._views) > self.max_views:
            self._views.popitem(last=False)


#: glibc's trim and mmap thresholds while an occluding camera is in use (bytes).
KEEP_FREED_BYTES = 256 * 2**20
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters


@cache
def keep_freed_memory() -> bool:
    """Ask glibc to keep freed memory instead of returning it to the kernel.

    Every view allocates and frees window-sized float32 arrays (0.1–1 MB); with glibc's default
    thresholds the heap top is trimmed and faulted in again each time, which took 40 % of a
    search run's time (sys time 6.8 s of 23.7 s; 0.4 s with these thresholds). Linux with glibc
    only; elsewhere (or if the call fails) nothing changes and False is returned."""
    name = ctypes.util.find_library("c")
    if sys.platform != "linux" or name is None:
        return False
    try:
        libc = ctypes.CDLL(name)
        return bool(
            libc.mallopt(_M_TRIM_THRESHOLD, KEEP_FREED_BYTES)
            and libc.mallopt(_M_MMAP_THRESHOLD, KEEP_FREED_BYTES)
        )
    except (OSError, AttributeError):
        return False


#: Shared by every occluding camera of a process: the views of one run's searches recur in the
#: next strategy's and the next seed's.
SHARED_CACHE = VisibilityCache()


@dataclass(frozen=True)
class OccludingCamera:
    """A search camera whose detections are what the rendered room shows (furniture occludes)."""

    intrinsics: CameraIntrinsics = DEFAULT_INTRINSICS
    height: float = CAMERA_HEIGHT_M
    cache: VisibilityCache = SHARED_CACHE
    name: str = "occluding"
    #: id of a ``placed`` sequence → (it, its key part): a world passes the same tuple per room.
    _placed: dict[int, tuple[Sequence[Placement], _Placed]] = field(
        default_factory=dict, compare=False, repr=False
    )
    _scenes: dict[tuple[str, str, _Placed, str | None], Scene] = field(
        default_factory=dict, compare=False, repr=False
    )

    def __post_init__(self) -> None:
        keep_freed_memory()

    def _scene(self, home: Home, room: str, placed: _Placed, opened: str | None) -> Scene:
        """The room's scene (an opened container taken out), built once per world and room:
        a search looks at one room from hundreds of poses."""
        key = (home.digest, room, placed, opened)
        scene = self._scenes.get(key)
        if scene is None:
            if len(self._scenes) >= PLACED_KEYS:
                self._scenes.clear()
            scene = room_scene(home, room, placed.items)
            if opened is not None:
                scene = scene.without(opened)
            self._scenes[key] = scene
        return scene

    def _placed_key(self, placed: Sequence[Placement]) -> _Placed:
        known = self._placed.get(id(placed))
        if known is not None and known[0] is placed:
            return known[1]
        if len(self._placed) >= PLACED_KEYS:
            self._placed.clear()
        key = _intern(_Placed(tuple(placed)))
        self._placed[id(placed)] = (placed, key)
        return key

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
        if not candidates:
            return ()
        areas = self.areas(home, room, pose, pitch, placed, opened)
        return tuple(
            Detection(p.cls, p.instance_id, float(areas[p.instance_id]), p.box.center)
            for p in candidates
            if areas[p.instance_id] > 0
        )

    def areas(
        self,
        home: Home,
        room: str,
        pose: Pose,
        pitch: float,
        placed: Sequence[Placement],
        opened: str | None,
    ) -> dict[str, int]:
        """Pixels of every object placed in ``room`` (``placed``) seen from ``pose``."""
        # Rounded for the key, and the view is computed at the rounded pose, so a cached
        # answer is exactly the answer for its key.
        x, y, yaw, tilt = (round(v, 6) for v in (pose.x, pose.y, pose.yaw, pitch))
        key: ViewKey = (home.digest, room, x, y, yaw, tilt, opened, self.height, self.intrinsics)
        placed_key = self._placed_key(placed)
        key += (placed_key,)
        found = self.cache.get(key)
        if found is not None:
            return found
        scene = self._scene(home, room, placed_key, opened)
        t = camera_to_map(Pose(x, y, yaw), height=self.height, pitch=tilt)
        areas = mask_areas(scene, [p.instance_id for p in placed], t, self.intrinsics)
        self.cache.put(key, areas)
        return areas
