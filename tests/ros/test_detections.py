"""The one converter from vision_msgs detections to the agent's Detection (ros/detections.py):
the pose, depth and 3-D inputs put objects where they are, areas read back what was drawn,
hypotheses become score and class distribution, and bad messages are refused saying why."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from objsearch.agent.camera_frames import DEFAULT_INTRINSICS, camera_to_map, project
from objsearch.agent.geometry import Pose
from objsearch.agent.world import Detection
from objsearch.ros import detections as conv
from objsearch.ros.builder import MessageBuilder
from objsearch.ros.images import depth_metres
from objsearch.ros.topics import TopicMap
from objsearch.ros.types import Distro

STAMP = 7 * 10**9 + 5
POSE = Pose(2.0, 1.0, math.radians(30))
K = DEFAULT_INTRINSICS
B = MessageBuilder(Distro.ROS2, TopicMap())
T = B.t
OPTICAL = B.frames.camera_optical


def hypothesis(cls: str, score: float) -> Any:
    return T["vision_msgs/msg/ObjectHypothesisWithPose"](
        hypothesis=T["vision_msgs/msg/ObjectHypothesis"](class_id=cls, score=score),
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            ),
            covariance=np.zeros(36),
        ),
    )


def boxes_2d(
    items: list[tuple[str, list[tuple[str, float]], tuple[float, float, float, float]]],
) -> Any:
    """A Detection2DArray in the optical frame: (id, hypotheses, (u, v, w, h)) each."""
    return B.detection_array(
        STAMP, OPTICAL, [(i, h[0][0], h, box, (0.0, 0.0, 0.0)) for i, h, box in items]
    )


def test_the_pose_input_keeps_what_the_stand_in_sent() -> None:
    sent = [
        Detection("Cup", "Cup|3", 1200.0, (1.5, -0.25, 0.9), 0.8, (("Cup", 0.8), ("Bowl", 0.2))),
        Detection("Apple", "Apple|1", 400.0, (3.0, 2.0, 0.75)),
    ]
    got = conv.from_pose_2d(B.detections(STAMP, POSE, sent), np.eye(4))
    assert [(d.object_class, d.instance_id, d.position, d.score) for d in got] == [
        (d.object_class, d.instance_id, d.position, d.score) for d in sent
    ]
    assert got[0].class_scores == (("Cup", 0.8), ("Bowl", 0.2))
    assert got[1].class_scores == (("Apple", 1.0),)
    # The box is drawn by the box camera; its area is the mask area the agent thresholds.
    assert all(d.mask_area > 0 for d in got)
    # A header frame other than the map: T_map_frame moves the positions.
    shift = np.eye(4)
    shift[:3, 3] = (10.0, 0.0, 0.0)
    moved = conv.from_pose_2d(B.detections(STAMP, POSE, sent), shift)
    assert moved[0].position == pytest.approx((11.5, -0.25, 0.9))


def test_the_best_hypothesis_is_the_class_and_all_are_the_distribution() -> None:
    c = conv.classes_of(
        [hypothesis("Bowl", 0.3), hypothesis("Cup", 0.6), hypothesis("Mug", 0.6)], "d"
    )
    # The best scoring (the first among ties) first, the rest in message order.
    assert (c.object_class, c.score, c.index) == ("Cup", 0.6, 1)
    assert c.distribution == (("Cup", 0.6), ("Bowl", 0.3), ("Mug", 0.6))


@pytest.mark.parametrize(
    ("results", "error"),
    [
        ([], "has no hypothesis"),
        ([hypothesis("", 0.7)], "a hypothesis without a class"),
        ([hypothesis("Cup", 1.5)], "has score 1.5, not in [0, 1]"),
        ([hypothesis("Cup", math.nan)], "not in [0, 1]"),
    ],
)
def test_hypotheses_that_say_nothing_are_refused(results: list[Any], error: str) -> None:
    with pytest.raises(conv.DetectionError, match=error.replace("[", r"\[").replace("]", r"\]")):
        conv.classes_of(results, "detection 0 ('x')")


def test_a_detection_without_an_id_gets_one_per_view() -> None:
    msg = boxes_2d(
        [
            ("", [("Cup", 0.9)], (100.0, 100.0, 20.0, 20.0)),
            ("", [("Cup", 0.7)], (300.0, 100.0, 20.0, 20.0)),
            ("track-4", [("Cup", 0.8)], (500.0, 100.0, 20.0, 20.0)),
        ]
    )
    got = conv.from_pose_2d(msg, np.eye(4))
    assert [d.instance_id for d in got] == [f"Cup@{STAMP}#0", f"Cup@{STAMP}#1", "track-4"]


def test_bad_2d_boxes_are_refused() -> None:
    with pytest.raises(conv.DetectionError, match="negative box size"):
        conv.from_pose_2d(boxes_2d([("a", [("Cup", 0.9)], (1.0, 1.0, -2.0, 3.0))]), np.eye(4))
    with pytest.raises(conv.DetectionError, match="non-finite"):
        conv.from_pose_2d(boxes_2d([("a", [("Cup", 0.9)], (1.0, 1.0, math.inf, 3.0))]), np.eye(4))


def depth_image(depth: np.ndarray[Any, Any]) -> Any:
    return B.image(STAMP, "32FC1", depth.astype(np.float32))


def test_the_depth_input_back_projects_the_box_centre_into_the_map() -> None:
    t_map_optical = camera_to_map(POSE)
    objects = np.array([[3.5, 2.2, 0.8], [4.0, 0.5, 1.2]])
    uv, z = project(objects.astype(np.float32), K, t_map_optical)
    depth = np.zeros(K.shape, dtype=np.float32)
    boxes = []
    for i, ((u, v), zi) in enumerate(zip(uv, z, strict=True)):
        col, row = round(float(u)), round(float(v))
        depth[row - 2 : row + 3, col - 2 : col + 3] = zi  # the object's surface around its centre
        boxes.append((f"o{i}", [("Cup", 0.9)], (float(u), float(v), 30.0, 40.0)))
    got, skipped = conv.from_depth_2d(
        boxes_2d(boxes), depth_metres(depth_image(depth)), K, t_map_optical
    )
    assert skipped == []
    assert [d.mask_area for d in got] == [1200.0, 1200.0]
    for d, p in zip(got, objects, strict=True):
        # The depth is read at the rounded pixel; the ray through the box centre itself.
        assert d.position == pytest.approx(tuple(p), abs=2e-3)


def test_the_depth_at_a_box_centre_is_the_median_of_the_valid_pixels_around_it() -> None:
    depth = np.zeros((10, 10), dtype=np.float32)
    depth[3:8, 3:8] = [[2.0, 2.0, 2.0, 2.0, np.nan]] * 5
    depth[5, 5] = 0.0  # no return at the centre itself
    depth[4, 4] = 9.0  # one outlier
    assert conv.depth_at(depth, 5.2, 4.8) == 2.0
    assert conv.depth_at(np.zeros((10, 10), dtype=np.float32), 5, 5) is None
    assert conv.depth_at(depth, -1, 5) is None
    assert conv.depth_at(depth, 5, 10) is None


def test_a_box_without_depth_is_left_out_saying_why_and_a_misaligned_image_is_refused() -> None:
    msg = boxes_2d([("o", [("Cup", 0.9)], (320.0, 240.0, 30.0, 40.0))])
    got, skipped = conv.from_depth_2d(msg, np.zeros(K.shape, dtype=np.float32), K, np.eye(4))
    assert got == [] and len(skipped) == 1
    assert "no valid depth at its box centre (320.0, 240.0)" in skipped[0]
    with pytest.raises(conv.DetectionError, match="aligned to the detector's image"):
        conv.from_depth_2d(msg, np.ones((240, 320), dtype=np.float32), K, np.eye(4))


def test_the_3d_input_reads_back_what_the_stand_in_drew() -> None:
    sent = [
        Detection("Cup", "Cup|3", 1200.0, (3.5, 2.2, 0.8), 0.8, (("Cup", 0.8), ("Bowl", 0.2))),
        Detection("Laptop", "Laptop|1", 9000.0, (4.0, 0.5, 1.2), 0.6),
    ]
    t_map_optical = camera_to_map(POSE)
    msg = B.detections_3d(STAMP, np.linalg.inv(t_map_optical), K, sent)
    got = conv.from_3d(msg, t_map_optical, K, np.eye(4))
    for d, s in zip(got, sent, strict=True):
        assert (d.object_class, d.instance_id, d.score) == (s.object_class, s.instance_id, s.score)
        assert d.position == pytest.approx(s.position, abs=1e-9)
        assert d.mask_area == pytest.approx(s.mask_area, rel=1e-6)
    assert got[0].class_scores == (("Cup", 0.8), ("Bowl", 0.2))
    assert got[1].class_scores == (("Laptop", 0.6),)


def box_3d(
    centre: tuple[float, float, float],
    size: tuple[float, float, float],
    q: tuple[float, float, float, float],
) -> Any:
    pose = T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=centre[0], y=centre[1], z=centre[2]),
        orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
    )
    det = T["vision_msgs/msg/Detection3D"](
        header=B.header(STAMP, OPTICAL),
        results=[hypothesis("Cup", 0.9)],
        bbox=T["vision_msgs/msg/BoundingBox3D"](
            center=pose, size=T["geometry_msgs/msg/Vector3"](x=size[0], y=size[1], z=size[2])
        ),
        id="",
    )
    return T["vision_msgs/msg/Detection3DArray"](header=B.header(STAMP, OPTICAL), detections=[det])


def test_a_3d_box_s_image_area_is_its_extent_across_the_optical_axis() -> None:
    size, z = (0.2, 0.4, 0.1), 2.0
    fxfy = K.fx * K.fy / z**2
    level = conv.from_3d(box_3d((0.0, 0.0, z), size, (0, 0, 0, 1)), np.eye(4), K, np.eye(4))
    assert level[0].mask_area == pytest.approx(0.2 * 0.4 * fxfy)
    # Turned 90° about the optical x axis: its 0.1 m side now spans the image's height.
    s = math.sin(math.pi / 4)
    turned = conv.from_3d(box_3d((0.0, 0.0, z), size, (s, 0, 0, s)), np.eye(4), K, np.eye(4))
    assert turned[0].mask_area == pytest.approx(0.2 * 0.1 * fxfy)
    # A centre behind the camera shows nothing.
    behind = conv.from_3d(box_3d((0.0, 0.0, -z), size, (0, 0, 0, 1)), np.eye(4), K, np.eye(4))
    assert behind[0].mask_area == 0.0
    assert behind[0].instance_id == f"Cup@{STAMP}#0"


def test_3d_boxes_in_another_frame_than_the_camera_s_are_measured_from_the_camera() -> None:
    # Boxes in the map frame, a camera at the origin facing +x: its optical x is the map's -y,
    # its optical y the map's -z, so a box's map y and z sides span the image.
    t_optical_map = np.linalg.inv(camera_to_map(Pose(0.0, 0.0, 0.0))).astype(np.float64)
    msg = box_3d((3.0, 0.0, 1.0), (0.3, 0.2, 0.1), (0, 0, 0, 1))
    (d,) = conv.from_3d(msg, np.eye(4), K, t_optical_map)
    assert d.position == pytest.approx((3.0, 0.0, 1.0))
    assert d.mask_area == pytest.approx(K.fx * 0.2 / 3.0 * K.fy * 0.1 / 3.0)


def test_bad_3d_boxes_are_refused() -> None:
    with pytest.raises(conv.DetectionError, match="not a unit quaternion"):
        conv.from_3d(box_3d((0, 0, 2), (0.1, 0.1, 0.1), (0, 0, 0, 2)), np.eye(4), K, np.eye(4))
    with pytest.raises(conv.DetectionError, match="negative box size"):
        conv.from_3d(box_3d((0, 0, 2), (0.1, -0.1, 0.1), (0, 0, 0, 1)), np.eye(4), K, np.eye(4))
    with pytest.raises(conv.DetectionError, match="non-finite"):
        conv.from_3d(
            box_3d((0, math.nan, 2), (0.1, 0.1, 0.1), (0, 0, 0, 1)), np.eye(4), K, np.eye(4)
        )


def test_a_command_s_view_is_stamped_at_or_after_arrival_and_after_the_clock_it_was_given_at() -> (
    None
):
    assert conv.view_not_before(arrival_ns=5, issued_ns=3) == 5  # it moved: its arrival
    assert conv.view_not_before(arrival_ns=5, issued_ns=5) == 6  # there already: a later frame
    assert conv.view_not_before(arrival_ns=2, issued_ns=5) == 6
