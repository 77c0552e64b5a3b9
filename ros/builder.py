"""Builders of the messages the robot publishes, for ROS 1 and ROS 2 alike.

``objsearch record`` writes these into bags and the on-robot runtime sends them (ROS 2 only), so a
message means the same wherever it was made: odometry and TF (REP-105 frames of the topic map),
camera info and images, ``vision_msgs/Detection2DArray`` (class and instance in the hypothesis and
id, the map-frame position as the hypothesis pose, the mask area as the box area) and the agent's
events as ``objsearch_msgs/Event``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from objsearch.agent.camera_frames import CameraIntrinsics
from objsearch.agent.geometry import Pose
from objsearch.agent.world import Detection
from objsearch.events import Event
from objsearch.events.record import encode_record
from objsearch.ros.topics import TopicMap
from objsearch.ros.types import Distro, typestore

if TYPE_CHECKING:
    import numpy.typing as npt
    from rosbags.typesys.store import Typestore

#: camera_link (x forward, z up) → its optical frame (x right, y down, z forward), REP 103:
#: the quaternion (x, y, z, w) of the rotation whose columns are the optical axes in camera_link.
OPTICAL_ROTATION = (-0.5, 0.5, -0.5, 0.5)


@dataclass(frozen=True, slots=True)
class BoxCamera:
    """The pinhole a detection's box is drawn in: the box is centred on the projection of the
    object's centre and its area is the reported mask area. The defaults are the simulator's
    camera (640 × 480, 90° horizontal field of view, 1 m above the floor); a test keeps them equal."""

    focal_px: float = 320 / math.tan(math.pi / 4)
    height: float = 1.0  # metres above the floor
    image_width: int = 640
    image_height: int = 480


DEFAULT_BOX_CAMERA = BoxCamera()


class MessageBuilder:
    """Builds the messages of one distro (ROS 1 headers carry ``seq``; ROS 2 ones do not)."""

    def __init__(
        self, distro: Distro, topic_map: TopicMap, camera: BoxCamera = DEFAULT_BOX_CAMERA
    ) -> None:
        self.distro = distro
        self.camera = camera  # draws the detections' boxes
        self.store: Typestore = typestore(distro)
        self.t = self.store.types
        self.frames = topic_map.frames
        self._seq = 0

    def header(self, stamp_ns: int, frame: str) -> Any:
        stamp = self.t["builtin_interfaces/msg/Time"](
            sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9
        )
        if self.distro is Distro.ROS1:
            self._seq += 1
            return self.t["std_msgs/msg/Header"](seq=self._seq, stamp=stamp, frame_id=frame)
        return self.t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def _quat(self, yaw: float) -> Any:
        return self._rotation((0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)))

    def _rotation(self, q: tuple[float, float, float, float]) -> Any:
        return self.t["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3])

    def _vec(self, x: float, y: float, z: float) -> Any:
        return self.t["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)

    def _transform(
        self,
        stamp: int,
        parent: str,
        child: str,
        xyz: tuple[float, float, float],
        q: tuple[float, float, float, float],
    ) -> Any:
        return self.t["geometry_msgs/msg/TransformStamped"](
            header=self.header(stamp, parent),
            child_frame_id=child,
            transform=self.t["geometry_msgs/msg/Transform"](
                translation=self._vec(*xyz), rotation=self._rotation(q)
            ),
        )

    def tf(self, stamp: int, pose: Pose) -> Any:
        f = self.frames
        return self.t["tf2_msgs/msg/TFMessage"](
            transforms=[
                self._transform(stamp, f.map, f.odom, (0.0, 0.0, 0.0), _yaw_q(0.0)),
                self._transform(stamp, f.odom, f.base, (pose.x, pose.y, 0.0), _yaw_q(pose.yaw)),
            ]
        )

    def tf_static(
        self, stamp: int, height: float, *, pitch: float = 0.0, optical: bool = False
    ) -> Any:
        """base → camera (``height`` up, tilted down by ``pitch``: a turn about its y axis) and,
        with ``optical``, camera → its optical frame."""
        f = self.frames
        tilt = (0.0, math.sin(pitch / 2), 0.0, math.cos(pitch / 2))
        transforms = [self._transform(stamp, f.base, f.camera, (0.0, 0.0, height), tilt)]
        if optical:
            transforms.append(
                self._transform(
                    stamp, f.camera, f.camera_optical, (0.0, 0.0, 0.0), OPTICAL_ROTATION
                )
            )
        return self.t["tf2_msgs/msg/TFMessage"](transforms=transforms)

    def odometry(self, stamp: int, pose: Pose, twist: tuple[float, float]) -> Any:
        import numpy as np

        t = self.t
        return t["nav_msgs/msg/Odometry"](
            header=self.header(stamp, self.frames.odom),
            child_frame_id=self.frames.base,
            pose=t["geometry_msgs/msg/PoseWithCovariance"](
                pose=t["geometry_msgs/msg/Pose"](
                    position=t["geometry_msgs/msg/Point"](x=pose.x, y=pose.y, z=0.0),
                    orientation=self._quat(pose.yaw),
                ),
                covariance=np.zeros(36, dtype=np.float64),
            ),
            twist=t["geometry_msgs/msg/TwistWithCovariance"](
                twist=t["geometry_msgs/msg/Twist"](
                    linear=self._vec(twist[0], 0.0, 0.0), angular=self._vec(0.0, 0.0, twist[1])
                ),
                covariance=np.zeros(36, dtype=np.float64),
            ),
        )

    def camera_info(self, stamp: int, k: CameraIntrinsics, frame: str) -> Any:
        """A distortion-free pinhole; K's principal point in OpenCV pixel coordinates (pixel
        centres at integers), the convention of ``CameraIntrinsics`` too."""
        import numpy as np

        fx, fy, cx, cy = k.fx, k.fy, k.cx, k.cy
        kk = np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], dtype=np.float64)
        r = np.eye(3, dtype=np.float64).ravel()
        p = np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], dtype=np.float64)
        roi = self.t["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        )
        fields: dict[str, Any] = {
            "header": self.header(stamp, frame),
            "height": k.height,
            "width": k.width,
            "distortion_model": "plumb_bob",
            "binning_x": 0,
            "binning_y": 0,
            "roi": roi,
        }
        if self.distro is Distro.ROS1:
            fields |= {"D": np.zeros(5, dtype=np.float64), "K": kk, "R": r, "P": p}
        else:
            fields |= {"d": np.zeros(5, dtype=np.float64), "k": kk, "r": r, "p": p}
        return self.t["sensor_msgs/msg/CameraInfo"](**fields)

    def image(self, stamp: int, encoding: str, pixels: npt.NDArray[Any]) -> Any:
        """A ``sensor_msgs/Image`` in the optical frame, little-endian, rows packed."""
        import numpy as np

        little = pixels.astype(pixels.dtype.newbyteorder("<"), copy=False)
        data = np.ascontiguousarray(little).view(np.uint8).ravel()
        height, width = pixels.shape[:2]
        return self.t["sensor_msgs/msg/Image"](
            header=self.header(stamp, self.frames.camera_optical),
            height=height,
            width=width,
            encoding=encoding,
            is_bigendian=0,
            step=len(data) // height,
            data=data,
        )

    def detections(self, stamp: int, pose: Pose, dets: Sequence[Detection]) -> Any:
        """The search's detections: boxes from the geometric camera model (``project``), each
        class hypothesis with its score (a perfect detector's: its class at 1)."""
        return self.detection_array(
            stamp,
            self.frames.camera,
            [
                (
                    d.instance_id,
                    d.object_class,
                    hypotheses(d),
                    project(self.camera, pose, d),
                    d.position,
                )
                for d in dets
            ],
        )

    def detections_3d(
        self,
        stamp: int,
        t_optical_map: npt.NDArray[Any],
        intrinsics: CameraIntrinsics,
        dets: Sequence[Detection],
    ) -> Any:
        """A detector node's ``Detection3DArray`` in the camera's optical frame: each box centred
        on the object, a cube whose image area at its centre's depth is the mask area
        (``objsearch.ros.detections.image_area`` reads it back), every class hypothesis with
        its score. ``t_optical_map`` maps map points into the optical frame at ``stamp``."""
        import numpy as np

        t = self.t
        items = []
        for d in dets:
            x, y, z, _ = t_optical_map @ np.array([*d.position, 1.0])
            side = (
                math.sqrt(max(d.mask_area, 0.0))
                * max(z, 0.0)
                / math.sqrt(intrinsics.fx * intrinsics.fy)
            )
            centre = t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=float(z)),
                orientation=self._rotation((0.0, 0.0, 0.0, 1.0)),
            )
            items.append(
                t["vision_msgs/msg/Detection3D"](
                    header=self.header(stamp, self.frames.camera_optical),
                    results=[self._hypothesis(cls, score, centre) for cls, score in hypotheses(d)],
                    bbox=t["vision_msgs/msg/BoundingBox3D"](
                        center=centre, size=self._vec(side, side, side)
                    ),
                    id=d.instance_id,
                )
            )
        return t["vision_msgs/msg/Detection3DArray"](
            header=self.header(stamp, self.frames.camera_optical), detections=items
        )

    def _hypothesis(self, cls: str, score: float, pose: Any) -> Any:
        import numpy as np

        t = self.t
        return t["vision_msgs/msg/ObjectHypothesisWithPose"](
            hypothesis=t["vision_msgs/msg/ObjectHypothesis"](class_id=cls, score=float(score)),
            pose=t["geometry_msgs/msg/PoseWithCovariance"](
                pose=pose, covariance=np.zeros(36, dtype=np.float64)
            ),
        )

    def detection_array(
        self,
        stamp: int,
        frame: str,
        dets: Sequence[
            tuple[
                str,
                str,
                float | Sequence[tuple[str, float]],
                tuple[float, float, float, float],
                tuple[float, float, float],
            ]
        ],
    ) -> Any:
        """(instance id, class, score — or every (class, score) hypothesis —, box (u, v, w, h)
        in pixels, map-frame position) each."""
        t = self.t
        items = []
        for instance_id, cls, scores, (u, v, w, h), position in dets:
            # The 3-D position is in the map frame, as the agent uses it.
            pose = t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](
                    x=float(position[0]), y=float(position[1]), z=float(position[2])
                ),
                orientation=self._quat(0.0),
            )
            pairs = [(cls, scores)] if isinstance(scores, float | int) else scores
            items.append(
                t["vision_msgs/msg/Detection2D"](
                    header=self.header(stamp, frame),
                    results=[self._hypothesis(c, p, pose) for c, p in pairs],
                    bbox=t["vision_msgs/msg/BoundingBox2D"](
                        center=t["vision_msgs/msg/Pose2D"](
                            position=t["vision_msgs/msg/Point2D"](x=u, y=v), theta=0.0
                        ),
                        size_x=w,
                        size_y=h,
                    ),
                    id=instance_id,
                )
            )
        return t["vision_msgs/msg/Detection2DArray"](
            header=self.header(stamp, self.frames.map), detections=items
        )

    def event(self, stamp: int, e: Event) -> Any:
        return self.t["objsearch_msgs/msg/Event"](
            header=self.header(stamp, self.frames.map),
            event_id=e.event_id,
            stream=e.stream,
            seq=e.seq,
            time_ns=e.time_ns,
            recorded_at_ns=e.recorded_at_ns,
            type=e.type,
            version=e.version,
            task_id=e.task_id or "",
            payload_json=json.dumps(
                dict(e.payload), sort_keys=True, separators=(",", ":"), ensure_ascii=False
            ),
            crc32=event_crc32(e),
        )


def hypotheses(d: Detection) -> tuple[tuple[str, float], ...]:
    """A detection's class hypotheses as a detector node sends them: its class distribution,
    the reported class first, or its class at its score alone."""
    return d.class_scores or ((d.object_class, d.score),)


def _yaw_q(yaw: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


def event_crc32(e: Event) -> int:
    """The checksum events.log stores for ``e`` (CRC-32 of its canonical JSON)."""
    return int(encode_record(e)[-9:-1], 16)


def project(camera: BoxCamera, pose: Pose, d: Detection) -> tuple[float, float, float, float]:
    """Centre (u, v) and size (w, h) in pixels of a detection whose mask area is known.

    The box has the camera model's aspect (the object's widest side × its height) scaled to
    the reported mask area, centred on the projection of the object's centre.
    """
    dx, dy = d.position[0] - pose.x, d.position[1] - pose.y
    bearing = math.atan2(dy, dx) - pose.yaw
    bearing = math.atan2(math.sin(bearing), math.cos(bearing))
    ahead = max(math.hypot(dx, dy) * math.cos(bearing), 0.1)
    f = camera.focal_px
    u = camera.image_width / 2 - f * math.tan(bearing)
    v = camera.image_height / 2 - f * (d.position[2] - camera.height) / ahead
    side = math.sqrt(max(d.mask_area, 0.0))
    return u, v, side, side
