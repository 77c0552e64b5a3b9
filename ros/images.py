"""ROS images and camera info → numpy: the one decoder of ``sensor_msgs/Image`` and
``CameraInfo``, shared by the bag pipeline (``pipeline/bags/rgbd.py``, a bag's RGB-D views) and
the robot's side (``runtime/detections_in.py``, the depth a detector's 2-D boxes are placed with):
the robot's code never imports the pipeline.

Depth follows REP 118: ``32FC1`` in metres (NaN, ±inf = no return) or ``16UC1`` in millimetres
(0 = no return); no return is 0 in the decoded array.
"""

from __future__ import annotations

from typing import Any, Final

import numpy as np
import numpy.typing as npt

from objsearch.agent.camera_frames import CameraIntrinsics, FloatArray

#: encoding → (numpy dtype, channels)
_ENCODINGS: Final = {
    "32FC1": ("f4", 1),
    "16UC1": ("u2", 1),
    "mono16": ("u2", 1),
    "8UC1": ("u1", 1),
    "mono8": ("u1", 1),
    "rgb8": ("u1", 3),
    "bgr8": ("u1", 3),
}


class ImageError(ValueError):
    """An image message whose encoding, size or data cannot be decoded."""


def decode_image(msg: Any) -> npt.NDArray[Any]:
    """(H, W) or (H, W, C) array of a ``sensor_msgs/Image`` (rows may be padded to ``step``)."""
    if msg.encoding not in _ENCODINGS:
        raise ImageError(f"encoding {msg.encoding!r} is not one of {', '.join(_ENCODINGS)}")
    kind, channels = _ENCODINGS[msg.encoding]
    dtype = np.dtype(kind).newbyteorder(">" if msg.is_bigendian else "<")
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    row = w * channels * dtype.itemsize
    data = np.asarray(msg.data, dtype=np.uint8)
    if h <= 0 or w <= 0 or step < row or data.size < h * step:
        raise ImageError(f"{w}×{h} {msg.encoding} image with step {step} has {data.size} bytes")
    rows = data[: h * step].reshape(h, step)[:, :row]
    pixels = np.ascontiguousarray(rows).view(dtype).astype(dtype.newbyteorder("="))
    return pixels.reshape((h, w, channels) if channels > 1 else (h, w))


def depth_metres(msg: Any) -> FloatArray:
    """A depth image in metres, 0 where the sensor had no return."""
    pixels = decode_image(msg)
    if msg.encoding == "32FC1":
        depth = pixels.astype(np.float32)
        depth[~np.isfinite(depth) | (depth < 0)] = 0.0  # REP 118: NaN, ±inf = no return
        return depth
    if msg.encoding == "16UC1":
        return (pixels.astype(np.float32) / np.float32(1000.0)).astype(np.float32)
    raise ImageError(f"depth encoding {msg.encoding!r}; expected 32FC1 (m) or 16UC1 (mm)")


def intrinsics_of(msg: Any) -> tuple[CameraIntrinsics, bool]:
    """The pinhole of a ``CameraInfo`` (ROS 1 ``K``/``D`` or ROS 2 ``k``/``d``) and whether it
    declares distortion."""
    k = np.asarray(getattr(msg, "k", None) if hasattr(msg, "k") else msg.K, dtype=np.float64)
    d = np.asarray(getattr(msg, "d", None) if hasattr(msg, "d") else msg.D, dtype=np.float64)
    if k.shape != (9,) or not np.isfinite(k).all() or k[0] <= 0 or k[4] <= 0:
        raise ValueError(f"camera info K {k.tolist()} is not a pinhole")
    intr = CameraIntrinsics(
        int(msg.width), int(msg.height), float(k[0]), float(k[4]), float(k[2]), float(k[5])
    )
    return intr, bool(np.any(d != 0))
