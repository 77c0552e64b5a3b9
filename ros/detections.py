"""A detector node's ``vision_msgs`` detections → the agent's :class:`Detection`: the one
converter, used live (:mod:`objsearch.runtime.detections_in`) and from a bag
(:mod:`objsearch.pipeline.bags.views`), so a recorded view means to a replay exactly what it
meant to the agent that received it.

What a detection becomes (docs/runtime.md, *Detections from any detector node*):

* **class, score, class distribution**: every ``ObjectHypothesisWithPose`` is a (class, score)
  pair; the best scoring one (the first among ties) is the detection's class and score, and all
  pairs, that one first, the rest in message order, its class distribution.
* **instance id**: the detection's ``id`` (a tracker's); a detector that leaves it empty gets
  ``<class>@<stamp>#<index>``, unique per view (no identity across views is claimed).
* **position** (map frame), by :data:`INPUTS`:

  - ``pose``: ``Detection2DArray`` whose best hypothesis's pose is the object's position in the
    array header's frame (what ``objsearch record`` writes and the stand-in robot sends by default);
  - ``depth``: ``Detection2DArray`` plus a depth image aligned to the image the detector ran on
    (same size as the ``CameraInfo``, same stamp as the array's header): the depth at the box
    centre's pixel (the median of the valid pixels of the 5×5 around it), back-projected
    through the camera info and put into the map by TF at the image stamp;
  - ``3d``: ``Detection3DArray``: the box centre, in the array header's frame, put into the map
    by TF at its stamp.

* **mask area** (pixels, what the classes' ``min_mask_area_px`` thresholds are written for):
  a 2-D box's area; a 3-D box's image area where its centre lies: its extents across the optical
  axis (the box turned into the camera's optical frame) over the centre's depth, times fx and fy
  of the camera info, rounded to 1e-6 px.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from objsearch.agent.world import Detection

if TYPE_CHECKING:
    import numpy.typing as npt

    from objsearch.agent.camera_frames import CameraIntrinsics

    Matrix = npt.NDArray[np.float64]

#: How a detector's positions are given (module docstring).
INPUTS: Final = ("pose", "depth", "3d")
#: The message type each input reads.
MESSAGE_TYPES: Final = {
    "pose": "vision_msgs/msg/Detection2DArray",
    "depth": "vision_msgs/msg/Detection2DArray",
    "3d": "vision_msgs/msg/Detection3DArray",
}
#: Half the side of the pixel window whose valid depths give a 2-D detection's depth.
DEPTH_WINDOW: Final = 2


class DetectionError(ValueError):
    """A detection message that cannot be turned into detections (says which and why)."""


def view_not_before(arrival_ns: int, issued_ns: int) -> int:
    """The earliest stamp of the camera view that answers a robot command: at or after the
    command's arrival (``arrival_ns``, the stamp of the pose that showed the robot at its goal)
    and later than ``issued_ns``, the robot's clock — the newest stamp heard from it — when the
    command was sent. The second bound matters when arrival can be stamped at that clock
    (Nav2's action result, taken at the newest stamp heard; a goal's arrival on odometry is a
    pose stamped after the clock, issue 45): a view of the command before (a turn whose view
    nobody waited for, still in flight) would otherwise be taken for this one's. It asks of
    the robot that each view be stamped later than anything it sent before the command, as a
    camera's frames are. The live agent (``runtime/rosworld.py``) and a bag's replay
    (``pipeline/bags/views.py``) pick views by this one rule."""
    return max(arrival_ns, issued_ns + 1)


def stamp_ns(header: Any) -> int:
    return int(header.stamp.sec) * 10**9 + int(header.stamp.nanosec)


def frame_of(header: Any) -> str:
    return str(header.frame_id).lstrip("/")


@dataclass(frozen=True, slots=True)
class Classes:
    """A detection's class hypotheses: the reported class, its score, and every (class, score)."""

    object_class: str
    score: float
    distribution: tuple[tuple[str, float], ...]
    index: int  # of the reported hypothesis in the message


def classes_of(results: Sequence[Any], what: str) -> Classes:
    """The hypotheses of one detection (ROS 2 ``hypothesis.class_id``, or ROS 1's ``id``)."""
    pairs: list[tuple[str, float]] = []
    for r in results:
        hyp = getattr(r, "hypothesis", r)
        cls = str(getattr(hyp, "class_id", getattr(hyp, "id", "")))
        score = float(hyp.score)
        if not cls:
            raise DetectionError(f"{what}: a hypothesis without a class")
        if not (math.isfinite(score) and 0.0 <= score <= 1.0):
            raise DetectionError(f"{what}: hypothesis {cls!r} has score {score}, not in [0, 1]")
        pairs.append((cls, score))
    if not pairs:
        raise DetectionError(f"{what} has no hypothesis")
    best = max(range(len(pairs)), key=lambda i: (pairs[i][1], -i))
    ordered = (pairs[best], *pairs[:best], *pairs[best + 1 :])
    return Classes(pairs[best][0], pairs[best][1], ordered, best)


def _instance(d: Any, cls: str, stamp: int, index: int) -> str:
    ident = str(getattr(d, "id", "") or "")
    return ident if ident else f"{cls}@{stamp}#{index}"


def _finite(values: Sequence[float], what: str) -> None:
    if not all(math.isfinite(v) for v in values):
        raise DetectionError(f"{what} has non-finite numbers {tuple(values)}")


def _in_map(t_map_frame: Matrix, point: Sequence[float]) -> tuple[float, float, float]:
    p = t_map_frame @ np.array([point[0], point[1], point[2], 1.0])
    return (float(p[0]), float(p[1]), float(p[2]))


def _box_2d(d: Any) -> tuple[float, float, float, float]:
    c = d.bbox.center
    u, v = (c.position.x, c.position.y) if hasattr(c, "position") else (c.x, c.y)
    return float(u), float(v), float(d.bbox.size_x), float(d.bbox.size_y)


def from_pose_2d(msg: Any, t_map_frame: Matrix) -> tuple[Detection, ...]:
    """``pose`` input: ``t_map_frame`` is T_map_header-frame at the array's stamp."""
    stamp = stamp_ns(msg.header)
    out = []
    for i, d in enumerate(msg.detections):
        what = f"detection {i} ({d.id!r})"
        c = classes_of(d.results, what)
        p = d.results[c.index].pose.pose.position
        _, _, w, h = _box_2d(d)
        _finite((p.x, p.y, p.z, w, h), what)
        if w < 0 or h < 0:
            raise DetectionError(f"{what} has a negative box size ({w}, {h})")
        out.append(
            Detection(
                c.object_class,
                _instance(d, c.object_class, stamp, i),
                w * h,
                _in_map(t_map_frame, (p.x, p.y, p.z)),
                c.score,
                c.distribution,
            )
        )
    return tuple(out)


def depth_at(depth: npt.NDArray[np.float32], u: float, v: float) -> float | None:
    """The depth (metres) at pixel (u, v): the median of the valid (> 0, finite) depths of the
    (2·DEPTH_WINDOW+1)² pixels around it; None when none is valid or it lies outside."""
    height, width = depth.shape
    col, row = round(u), round(v)
    if not (0 <= col < width and 0 <= row < height):
        return None
    k = DEPTH_WINDOW
    window = depth[max(row - k, 0) : row + k + 1, max(col - k, 0) : col + k + 1]
    valid = window[np.isfinite(window) & (window > 0)]
    return float(np.median(valid)) if valid.size else None


def from_depth_2d(
    msg: Any,
    depth: npt.NDArray[np.float32],
    camera: CameraIntrinsics,
    t_map_camera: Matrix,
) -> tuple[list[Detection], list[str]]:
    """``depth`` input: ``depth`` in metres (0 = no return) aligned to ``camera``, and
    T_map_optical-frame at the image's stamp. Returns the detections and, per detection left
    out, why (no valid depth at its box centre)."""
    if depth.shape != camera.shape:
        raise DetectionError(
            f"depth image {depth.shape[1]}×{depth.shape[0]} is not the camera info's "
            f"{camera.width}×{camera.height}: it must be aligned to the detector's image"
        )
    stamp = stamp_ns(msg.header)
    out, skipped = [], []
    for i, d in enumerate(msg.detections):
        what = f"detection {i} ({d.id!r})"
        c = classes_of(d.results, what)
        u, v, w, h = _box_2d(d)
        _finite((u, v, w, h), what)
        if w < 0 or h < 0:
            raise DetectionError(f"{what} has a negative box size ({w}, {h})")
        z = depth_at(depth, u, v)
        if z is None:
            skipped.append(f"{what}: no valid depth at its box centre ({u:.1f}, {v:.1f})")
            continue
        point = ((u - camera.cx) / camera.fx * z, (v - camera.cy) / camera.fy * z, z)
        out.append(
            Detection(
                c.object_class,
                _instance(d, c.object_class, stamp, i),
                w * h,
                _in_map(t_map_camera, point),
                c.score,
                c.distribution,
            )
        )
    return out, skipped


def _quaternion_matrix(q: Any) -> Matrix:
    x, y, z, w = float(q.x), float(q.y), float(q.z), float(q.w)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not math.isfinite(n) or abs(n - 1.0) > 1e-3:
        raise DetectionError(f"box orientation ({x}, {y}, {z}, {w}) is not a unit quaternion")
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def image_area(
    size: Sequence[float], r_camera_box: Matrix, centre_camera: Sequence[float], camera: Any
) -> float:
    """A 3-D box's image area where its centre lies: its extents across the optical axis (the
    box's axes turned by ``r_camera_box`` into the optical frame) over the centre's depth,
    times fx·fy; 0 for a centre behind the camera."""
    z = float(centre_camera[2])
    if z <= 0:
        return 0.0
    extents = np.abs(r_camera_box) @ np.asarray(size, dtype=np.float64)
    return round(float(camera.fx * extents[0] / z * camera.fy * extents[1] / z), 6)


def from_3d(
    msg: Any, t_map_frame: Matrix, camera: CameraIntrinsics, t_camera_frame: Matrix
) -> tuple[Detection, ...]:
    """``3d`` input: T_map_header-frame and T_optical_header-frame at the array's stamp, and the
    camera whose image the areas are measured in."""
    stamp = stamp_ns(msg.header)
    out = []
    for i, d in enumerate(msg.detections):
        what = f"detection {i} ({d.id!r})"
        c = classes_of(d.results, what)
        p, s = d.bbox.center.position, d.bbox.size
        _finite((p.x, p.y, p.z, s.x, s.y, s.z), what)
        if min(s.x, s.y, s.z) < 0:
            raise DetectionError(f"{what} has a negative box size ({s.x}, {s.y}, {s.z})")
        rotation = _quaternion_matrix(d.bbox.center.orientation)
        centre_cam = t_camera_frame @ np.array([p.x, p.y, p.z, 1.0])
        area = image_area(
            (s.x, s.y, s.z), t_camera_frame[:3, :3] @ rotation, centre_cam[:3], camera
        )
        out.append(
            Detection(
                c.object_class,
                _instance(d, c.object_class, stamp, i),
                area,
                _in_map(t_map_frame, (p.x, p.y, p.z)),
                c.score,
                c.distribution,
            )
        )
    return tuple(out)
