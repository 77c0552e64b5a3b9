"""A detector node's detections in, as the agent's camera views (docs/runtime.md, *Detections
from any detector node*).

:class:`DetectionInput` subscribes to the detections topic with the message type its
``[detections] input`` reads and, as that input needs, to camera info, the aligned depth image
and TF, and hands each view — ``(stamp, detections in the map frame)`` — to ``on_view`` once it
can be placed: a view waits (at most :data:`HELD` of them) until TF reaches its stamp and, for
``depth``, until the depth image of its stamp has come. The conversion is
:mod:`objsearch.ros.detections`, the same a bag's replay uses.
"""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from objsearch.agent.camera_frames import CameraIntrinsics
from objsearch.agent.world import Detection
from objsearch.ros import detections as conv
from objsearch.ros.errors import TransformError
from objsearch.ros.images import ImageError, depth_metres, intrinsics_of
from objsearch.ros.tf import TransformBuffer
from objsearch.runtime import messages as m
from objsearch.runtime.config import RuntimeConfig
from objsearch.runtime.errors import MessageError

if TYPE_CHECKING:
    import numpy.typing as npt

    from objsearch.runtime.node import Node

log = logging.getLogger("objsearch.agent")

CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
IMAGE = "sensor_msgs/msg/Image"
#: Views (and depth images) held while TF or their depth image has not come yet; older ones are
#: dropped with a log line.
HELD = 32
#: TF samples older than this (robot time) behind the newest are forgotten (tf2 keeps 10 s).
TF_CACHE_NS = 10 * 10**9
#: The largest depth image read (a 1920×1080 32FC1 image is 8.3 MB).
MAX_DEPTH_BYTES = 64 * 1024 * 1024

View = Callable[[int, tuple[Detection, ...]], None]


class DetectionInput:
    def __init__(self, node: Node, config: RuntimeConfig, on_view: View) -> None:
        self.config = config
        self.input = config.detections.input
        self.on_view = on_view
        self.map_frame = config.pose.map_frame
        self._lock = threading.Lock()
        self.tf = TransformBuffer()
        self.camera: CameraIntrinsics | None = None
        self._camera_frame: str | None = None
        self._depth: OrderedDict[int, tuple[str, npt.NDArray[np.float32]]] = OrderedDict()
        self._held: OrderedDict[tuple[int, int], Any] = OrderedDict()
        self._arrivals = 0
        self.dropped = 0
        t, q = config.topics, config.qos
        node.subscribe(t.detections, conv.MESSAGE_TYPES[self.input], q.detections, self._on_array)
        # TF: the pose input needs it only for a header frame other than the map.
        node.subscribe(t.tf, m.TF, q.tf, self._on_tf)
        node.subscribe(t.tf_static, m.TF, q.tf_static, lambda msg: self._on_tf(msg, True))
        if self.input != "pose":
            node.subscribe(t.camera_info, CAMERA_INFO, q.camera, self._on_camera_info)
        if self.input == "depth":
            node.subscribe(t.depth, IMAGE, q.camera, self._on_depth, max_bytes=MAX_DEPTH_BYTES)

    # -- inputs, each on a middleware thread ---------------------------------------------------

    def _on_tf(self, msg: Any, static: bool = False) -> None:
        with self._lock:
            try:
                for parent, child, ns, xyz, q in m.transforms_of(msg):
                    self.tf.add(parent, child, ns, xyz, q, static=static)
            except TransformError as exc:
                raise MessageError(str(exc)) from None
            if self.tf.latest_ns is not None:
                self.tf.forget_before(self.tf.latest_ns - TF_CACHE_NS)
        self._flush()

    def _on_camera_info(self, msg: Any) -> None:
        try:
            camera, _ = intrinsics_of(msg)
        except ValueError as exc:
            raise MessageError(str(exc)) from None
        with self._lock:
            self.camera, self._camera_frame = camera, conv.frame_of(msg.header)
        self._flush()

    def _on_depth(self, msg: Any) -> None:
        try:
            depth = depth_metres(msg)
        except ImageError as exc:
            raise MessageError(f"depth image: {exc}") from None
        with self._lock:
            self._depth[m.stamp_ns(msg.header)] = (conv.frame_of(msg.header), depth)
            while len(self._depth) > HELD:
                self._depth.popitem(last=False)
        self._flush()

    def _on_array(self, msg: Any) -> None:
        with self._lock:
            self._arrivals += 1
            self._held[(m.stamp_ns(msg.header), self._arrivals)] = msg
            while len(self._held) > HELD:
                (stamp, _), _old = self._held.popitem(last=False)
                self.dropped += 1
                log.warning(
                    "detections stamped %d dropped: %s",
                    stamp,
                    self._waiting_for(stamp, _old),
                )
        self._flush()

    # -- placing the views ---------------------------------------------------------------------

    def _flush(self) -> None:
        ready: list[tuple[int, tuple[Detection, ...]]] = []
        failed: list[str] = []
        with self._lock:
            for key, msg in list(self._held.items()):
                try:
                    dets = self._convert(msg)
                except _NotYet:
                    continue
                except (conv.DetectionError, TransformError) as exc:
                    failed.append(f"detections stamped {key[0]}: {exc}")
                    dets = None
                del self._held[key]
                if dets is not None:
                    ready.append((key[0], dets))
        for stamp, dets in ready:
            self.on_view(stamp, dets)
        if failed:
            raise MessageError("; ".join(failed))

    def _transform(self, target: str, frame: str, stamp: int) -> npt.NDArray[np.float64]:
        if frame == target:
            return np.eye(4)
        latest = self.tf.latest_common_ns(target, frame)
        if latest is not None and latest < stamp:
            raise _NotYet
        try:
            return self.tf.lookup(target, frame, stamp)
        except TransformError:
            if latest is None:
                raise _NotYet from None  # the frames are not connected yet
            raise

    def _convert(self, msg: Any) -> tuple[Detection, ...]:
        stamp, frame = m.stamp_ns(msg.header), conv.frame_of(msg.header)
        if self.input == "pose":
            return conv.from_pose_2d(msg, self._transform(self.map_frame, frame, stamp))
        if self.camera is None:
            raise _NotYet
        if self.input == "3d":
            t_map = self._transform(self.map_frame, frame, stamp)
            return conv.from_3d(msg, t_map, self.camera, self._camera_from(frame, stamp, t_map))
        if stamp not in self._depth:
            raise _NotYet
        depth_frame, depth = self._depth[stamp]
        dets, skipped = conv.from_depth_2d(
            msg, depth, self.camera, self._transform(self.map_frame, depth_frame, stamp)
        )
        for why in skipped:
            log.info("detections stamped %d: %s", stamp, why)
        return tuple(dets)

    def _camera_from(
        self, frame: str, stamp: int, t_map_frame: npt.NDArray[np.float64]
    ) -> npt.NDArray[np.float64]:
        """T_optical_frame: the detections' frame seen from the camera the areas are measured in
        (the camera info's frame)."""
        optical = self._camera_frame
        if optical is None or optical == frame:
            return np.eye(4)
        t_map_optical = self._transform(self.map_frame, optical, stamp)
        return np.linalg.inv(t_map_optical) @ t_map_frame

    def _waiting_for(self, stamp: int, msg: Any) -> str:
        if self.input != "pose" and self.camera is None:
            return f"no camera info on {self.config.topics.camera_info}"
        if self.input == "depth" and stamp not in self._depth:
            return f"no depth image of that stamp on {self.config.topics.depth}"
        return f"TF did not reach that stamp ({self.config.topics.tf})"


class _NotYet(Exception):
    """A view that cannot be placed yet (TF, camera info or its depth image still to come)."""
