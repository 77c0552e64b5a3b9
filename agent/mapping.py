"""Building the semantic map from RGB-D frames and instance masks (paper §4.3, §5.1 (a)–(c)).

1. **Survey** (:func:`survey_poses`): per room, sampling points on the boundary of its viewpoints —
   the boundary viewpoint nearest the boundary's median coordinate (the paper's rule; with
   ``points_per_room`` > 1, that rule applied to each angular sector of the boundary) — and a view
   every 45° at each.
2. **Local reconstruction**: each frame's masked depth of static classes is back-projected into a
   semantic point cloud in the map frame (:func:`backproject_labels`, torch).
3. **Global reconstruction**: the points vote for their class in a voxel grid per room
   (:class:`VoxelGrid`, torch; on a GPU when one is present). A voxel takes the class with most votes.
4. **Top-down projection** per class, closed by one 3×3 step and split into instances by 8-connected
   components (OpenCV). Each instance's loc_s is the centre of mass of its voxels, N_s the room's
   viewpoint nearest to it and θ_s the heading from N_s to loc_s.

The builder consumes :class:`MaskedDepth` views — depth, intrinsics, camera pose and masks —
whatever produced them: the simulator's frames run through a
:class:`~objsearch.agent.detect.Detector` (:func:`detected`), or a bag's depth, instance image,
camera info and TF (``objsearch.pipeline.bags.rgbd``). Same views → the same map, to the bit.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from objsearch.agent.camera_frames import CameraIntrinsics, Float64Array, FloatArray, RGBDFrame
from objsearch.agent.detect import Detector, MaskDetection
from objsearch.agent.geometry import Point, Pose, heading
from objsearch.agent.home import Box
from objsearch.agent.navmap import NavigationMap
from objsearch.agent.semmap import MappedStatic, SemanticMap

if TYPE_CHECKING:
    # Only fusing views needs torch (the ``torch`` extra): it is imported where they are fused, so
    # the survey's poses (``record --mapping-sweep``) need none; ``objsearch map build`` checks
    # first that it is installed (``agent/extras.py``).
    import torch

YAW_STEP = math.pi / 4  # "a view every 45 degrees" (§4.3)
#: "container type, such as refrigerator and microwave oven" (§5.1): the classes the robot opens.
CONTAINER_CLASSES = frozenset({"Fridge", "Microwave"})


@dataclass(frozen=True, slots=True)
class MappingConfig:
    voxel: float = 0.05  # metres
    z_max: float = 2.5  # the grid's height above the floor
    room_margin: float = 1.5  # grid extends this far beyond the room's outermost viewpoints
    min_votes: int = 1  # points a voxel needs to be occupied
    min_cells: int = 2  # top-down cells an instance needs (smaller ones are dropped as noise)
    points_per_room: int = 1


# -- survey -----------------------------------------------------------------------------------


def boundary_viewpoints(navmap: NavigationMap, room: str) -> tuple[Point, ...]:
    """Viewpoints missing one of their four grid neighbours."""
    pts = set(navmap.viewpoints(room))
    g = navmap.grid
    return tuple(
        sorted(
            p
            for p in pts
            if any(
                Point(round(p.x + dx, 4), round(p.y + dy, 4)) not in pts
                for dx, dy in ((g, 0), (-g, 0), (0, g), (0, -g))
            )
        )
    )


def sampling_points(navmap: NavigationMap, room: str, k: int = 1) -> tuple[Point, ...]:
    """The paper's sampling point (boundary viewpoint nearest the boundary's per-axis median);
    for k > 1 the same rule on each of k equal angular sectors around the viewpoints' centroid."""
    if k < 1:
        raise ValueError(f"points per room must be at least 1, not {k}")
    edge = boundary_viewpoints(navmap, room)
    if k == 1:
        return (_median_point(edge),)
    vps = navmap.viewpoints(room)
    cx = statistics.fmean(p.x for p in vps)
    cy = statistics.fmean(p.y for p in vps)
    sectors: list[list[Point]] = [[] for _ in range(k)]
    for p in edge:
        angle = math.atan2(p.y - cy, p.x - cx) % math.tau
        sectors[min(int(angle / (math.tau / k)), k - 1)].append(p)
    return tuple(_median_point(s) for s in sectors if s)


def _median_point(points: Sequence[Point]) -> Point:
    mx = statistics.median(p.x for p in points)
    my = statistics.median(p.y for p in points)
    return min(points, key=lambda p: (math.hypot(p.x - mx, p.y - my), p))


def survey_poses(
    navmap: NavigationMap, rooms: Iterable[str], points_per_room: int = 1
) -> tuple[tuple[str, Pose], ...]:
    """(room, pose) of every view of the survey: each sampling point, yaw 0°, 45°, …, 315°."""
    return tuple(
        (room, Pose(p.x, p.y, i * YAW_STEP))
        for room in rooms
        for p in sampling_points(navmap, room, points_per_room)
        for i in range(round(math.tau / YAW_STEP))
    )


# -- back-projection and fusion -------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class MaskedDepth:
    """What fusion needs of one view: depth (metres along the optical axis, 0 = no return), the
    camera, its pose (``T_map_camera``, optical frame → map) and the masks seen in it."""

    depth: FloatArray
    intrinsics: CameraIntrinsics
    T_map_camera: Float64Array
    detections: tuple[MaskDetection, ...]
    stamp_ns: int = 0

    @property
    def position(self) -> tuple[float, float, float]:
        x, y, z = (float(v) for v in self.T_map_camera[:3, 3])
        return (x, y, z)


def detected(frames: Iterable[RGBDFrame], detector: Detector) -> Iterator[MaskedDepth]:
    """The views of rendered (or otherwise captured) frames with a detector's masks."""
    for frame in frames:
        yield MaskedDepth(
            frame.depth,
            frame.intrinsics,
            frame.T_map_camera,
            detector.detect(frame),
            frame.stamp_ns,
        )


def default_device() -> torch.device:
    import torch

    return torch.device("cuda" if torch.cuda.is_available() else "cpu")


def label_image(
    detections: Sequence[MaskDetection], classes: Sequence[str], shape: tuple[int, int]
) -> npt.NDArray[np.int64]:
    """(H, W) class index per pixel (-1: none), from the masks of the given classes; where masks
    overlap the higher score wins (ties: the later mask)."""
    index = {c: i for i, c in enumerate(classes)}
    labels = np.full(shape, -1, dtype=np.int64)
    for det in sorted(detections, key=lambda d: d.score):
        i = index.get(det.cls)
        if i is not None:
            labels[det.mask] = i
    return labels


def backproject_labels(
    depth: torch.Tensor,
    labels: torch.Tensor,
    rays: torch.Tensor,
    T_map_camera: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Map-frame points (N, 3) and class indices (N,) of the labelled pixels with depth.

    ``rays`` is (H, W, 3) with z = 1 (:meth:`CameraIntrinsics.rays`). The rotation is written out
    per component: a (N, 3) × (3, 3) product goes through BLAS, which is slow for so thin a matrix.
    """
    import torch

    valid = ((depth > 0) & (labels >= 0)).view(-1)
    idx = torch.nonzero(valid).squeeze(1)
    z = depth.view(-1).index_select(0, idx)
    flat = rays.view(-1, 3)
    x = flat[:, 0].index_select(0, idx) * z
    y = flat[:, 1].index_select(0, idx) * z
    r, t = T_map_camera[:3, :3], T_map_camera[:3, 3]
    points = torch.stack([r[i, 0] * x + r[i, 1] * y + r[i, 2] * z + t[i] for i in range(3)], dim=1)
    return points, labels.view(-1).index_select(0, idx)


@dataclass(frozen=True, slots=True)
class GridSpec:
    origin: tuple[float, float, float]  # map-frame corner of voxel (0, 0, 0)
    shape: tuple[int, int, int]
    voxel: float

    @classmethod
    def around(cls, points: Sequence[Point], config: MappingConfig) -> GridSpec:
        m, v = config.room_margin, config.voxel
        x0 = min(p.x for p in points) - m
        y0 = min(p.y for p in points) - m
        nx = math.ceil((max(p.x for p in points) + m - x0) / v)
        ny = math.ceil((max(p.y for p in points) + m - y0) / v)
        return cls((x0, y0, 0.0), (nx, ny, math.ceil(config.z_max / v)), v)

    def centre(self, index: npt.NDArray[np.int64]) -> npt.NDArray[np.float64]:
        """Map-frame centres of voxels given as (N, 3) integer indices."""
        out: npt.NDArray[np.float64] = np.asarray(self.origin) + (index + 0.5) * self.voxel
        return out


class VoxelGrid:
    """Class votes per voxel: a flat (X·Y·Z·C) int32 tensor, added to in place."""

    def __init__(self, spec: GridSpec, n_classes: int, device: torch.device | None = None) -> None:
        import torch

        self.spec = spec
        self.n_classes = n_classes
        self.device = device or default_device()
        nx, ny, nz = spec.shape
        self.votes = torch.zeros(nx * ny * nz * n_classes, dtype=torch.int32, device=self.device)
        self._origin = torch.tensor(spec.origin, dtype=torch.float32, device=self.device)
        self._shape = torch.tensor(spec.shape, dtype=torch.int64, device=self.device)

    def integrate(self, points: torch.Tensor, labels: torch.Tensor) -> int:
        """Add one vote per point to its voxel's class; points outside the grid are dropped.
        Returns the number of votes added."""
        import torch

        idx = torch.floor((points - self._origin) / self.spec.voxel).to(torch.int64)
        inside = ((idx >= 0) & (idx < self._shape)).all(dim=1)
        idx, lab = idx[inside], labels[inside]
        _, ny, nz = self.spec.shape
        flat = ((idx[:, 0] * ny + idx[:, 1]) * nz + idx[:, 2]) * self.n_classes + lab
        self.votes.index_add_(0, flat, torch.ones_like(flat, dtype=torch.int32))
        return int(flat.shape[0])

    def labels(self, min_votes: int = 1) -> npt.NDArray[np.int64]:
        """(X, Y, Z) winning class per voxel, -1 where fewer than ``min_votes`` points fell.
        Ties go to the lower class index (torch's argmax returns the first maximum)."""
        votes = self.votes.view(*self.spec.shape, self.n_classes)
        best = votes.argmax(dim=3)
        best[votes.sum(dim=3) < min_votes] = -1
        out: npt.NDArray[np.int64] = best.cpu().numpy()
        return out


# -- instances ----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class BuiltInstance:
    id: str
    cls: str
    room: str
    centroid: tuple[float, float, float]  # centre of mass of the instance's voxels
    box: Box  # the voxels' bounding box
    cells: int  # top-down footprint, grid cells
    voxels: int


@dataclass(frozen=True)
class BuiltMap:
    semmap: SemanticMap
    instances: tuple[BuiltInstance, ...]
    frames: int
    points: int  # votes fused


class SemanticMapBuilder:
    """Fuses frames and their masks into per-room voxel grids, then extracts the semantic map."""

    def __init__(
        self,
        navmap: NavigationMap,
        classes: Sequence[str],
        config: MappingConfig | None = None,
        *,
        device: torch.device | None = None,
    ) -> None:
        self.navmap = navmap
        self.classes = tuple(classes)
        self.config = config or MappingConfig()
        self.device = device or default_device()
        self.grids: dict[str, VoxelGrid] = {}
        self.frames = 0
        self.points = 0
        self._rays: dict[object, torch.Tensor] = {}

    def grid(self, room: str) -> VoxelGrid:
        if room not in self.grids:
            spec = GridSpec.around(self.navmap.viewpoints(room), self.config)
            self.grids[room] = VoxelGrid(spec, len(self.classes), self.device)
        return self.grids[room]

    def add(self, view: MaskedDepth) -> None:
        """Fuse one view into the grid of the room the camera stands in."""
        import torch

        x, y, _ = view.position
        grid = self.grid(self.navmap.room_at(x, y))
        labels = label_image(view.detections, self.classes, view.intrinsics.shape)
        rays = self._rays.get(view.intrinsics)
        if rays is None:
            rays = torch.from_numpy(view.intrinsics.rays().copy()).to(self.device)
            self._rays[view.intrinsics] = rays
        points, lab = backproject_labels(
            torch.from_numpy(view.depth).to(self.device),
            torch.from_numpy(labels).to(self.device),
            rays,
            torch.from_numpy(view.T_map_camera.astype(np.float32)).to(self.device),
        )
        self.points += grid.integrate(points, lab)
        self.frames += 1

    def fuse(self, views: Iterable[MaskedDepth]) -> None:
        for view in views:
            self.add(view)

    def build(self) -> BuiltMap:
        import cv2

        instances: list[BuiltInstance] = []
        mapped: list[MappedStatic] = []
        kernel = np.ones((3, 3), np.uint8)
        for room in sorted(self.grids):
            grid = self.grids[room]
            labels = grid.labels(self.config.min_votes)
            found: list[tuple[str, float, float, BuiltInstance]] = []
            for ci, cls in enumerate(self.classes):
                occupied = labels == ci
                top = occupied.any(axis=2).astype(np.uint8)
                if not top.any():
                    continue
                # One closing step joins an object's pieces split by a pixel-wide gap of votes.
                top = cv2.morphologyEx(top, cv2.MORPH_CLOSE, kernel)
                n, comp, stats, _ = cv2.connectedComponentsWithStats(top, connectivity=8)
                for k in range(1, n):
                    cells = int(stats[k, cv2.CC_STAT_AREA])
                    vox = np.argwhere(occupied & (comp == k)[:, :, None])
                    if cells < self.config.min_cells or len(vox) == 0:
                        continue
                    centres = grid.spec.centre(vox)
                    c = centres.mean(axis=0)
                    half = grid.spec.voxel / 2
                    lo, hi = centres.min(axis=0) - half, centres.max(axis=0) + half
                    box = Box(
                        tuple(round(float(v), 4) for v in (lo + hi) / 2),  # type: ignore[arg-type]
                        tuple(round(float(v), 4) for v in hi - lo),  # type: ignore[arg-type]
                    )
                    centroid = (round(float(c[0]), 4), round(float(c[1]), 4), round(float(c[2]), 4))
                    inst = BuiltInstance("", cls, room, centroid, box, cells, len(vox))
                    found.append((cls, centroid[0], centroid[1], inst))
            found.sort(key=lambda f: (f[0], f[1], f[2]))
            counters: dict[str, int] = {}
            for cls, cx, cy, inst in found:
                counters[cls] = counters.get(cls, 0) + 1
                ident = f"{room}/{cls}#{counters[cls]}"
                inst = BuiltInstance(
                    ident, cls, room, inst.centroid, inst.box, inst.cells, inst.voxels
                )
                instances.append(inst)
                loc = Point(cx, cy)
                vp = self.navmap.nearest_viewpoint(cx, cy, room)
                mapped.append(
                    MappedStatic(
                        id=ident,
                        cls=cls,
                        room=room,
                        box=inst.box,
                        container=cls in CONTAINER_CLASSES,
                        viewpoint=vp,
                        view_yaw=heading(vp, loc),
                        centroid=loc,
                    )
                )
        return BuiltMap(SemanticMap(tuple(mapped)), tuple(instances), self.frames, self.points)
