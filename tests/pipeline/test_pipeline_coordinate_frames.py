"""Unity (AI2-THOR) <-> ROS REP-103 conversion with poses whose meaning is known."""

from __future__ import annotations

import math

import numpy as np
import pytest

from objsearch.pipeline import coordinate_frames


@pytest.mark.parametrize(
    ("unity_deg", "ros_rad"),
    [(0, 0.0), (90, -math.pi / 2), (180, math.pi), (270, math.pi / 2), (-90, math.pi / 2)],
)
def test_alfred_yaws(unity_deg: float, ros_rad: float) -> None:
    assert coordinate_frames.unity_yaw_to_ros(unity_deg) == pytest.approx(ros_rad, abs=1e-12)
    assert coordinate_frames.ros_yaw_to_unity(ros_rad) == pytest.approx(unity_deg % 360, abs=1e-9)


def test_yaw_wraps_into_half_open_interval() -> None:
    # -pi and pi are the same heading; only pi is allowed.
    assert coordinate_frames.wrap_angle(-math.pi) == math.pi
    assert coordinate_frames.wrap_angle(3 * math.pi) == pytest.approx(math.pi)
    for deg in range(-720, 721, 15):
        yaw = coordinate_frames.unity_yaw_to_ros(deg)
        assert -math.pi < yaw <= math.pi
        assert coordinate_frames.ros_yaw_to_unity(yaw) == pytest.approx(deg % 360, abs=1e-9)


def test_fridge_pose_of_floorplan2_faces_the_fridge() -> None:
    # ALFRED: agent at Unity (x=-0.75, z=0.0), yaw 270, opens Fridge|-01.76|+00.00|+00.01.
    agent = coordinate_frames.unity_floor_to_ros(-0.75, 0.0)
    fridge = coordinate_frames.unity_to_ros((-1.76, 0.0, 0.01))
    yaw = coordinate_frames.unity_yaw_to_ros(270)
    assert agent == pytest.approx((0.0, 0.75))
    assert fridge == pytest.approx((0.01, 1.76, 0.0))
    assert yaw == pytest.approx(math.pi / 2)  # ROS +y, where the fridge is
    heading = math.atan2(fridge[1] - agent[1], fridge[0] - agent[0])
    assert heading == pytest.approx(yaw, abs=0.02)


def test_points_and_sizes_round_trip() -> None:
    p = (1.25, 0.9, -3.5)
    assert coordinate_frames.unity_to_ros(p) == (-3.5, -1.25, 0.9)
    assert coordinate_frames.ros_to_unity(coordinate_frames.unity_to_ros(p)) == p
    assert coordinate_frames.ros_floor_to_unity(
        *coordinate_frames.unity_floor_to_ros(1.25, -3.5)
    ) == (1.25, -3.5)
    size = (0.7179, 1.8184, 0.87)  # FloorPlan2 fridge, Unity (sx, sy, sz)
    assert coordinate_frames.unity_size_to_ros(size) == (0.87, 0.7179, 1.8184)
    assert coordinate_frames.ros_size_to_unity(coordinate_frames.unity_size_to_ros(size)) == size


def test_mapping_flips_handedness_and_yaw_follows_the_map() -> None:
    basis = np.array([coordinate_frames.unity_to_ros(tuple(row)) for row in np.eye(3)]).T
    assert np.linalg.det(basis) == pytest.approx(-1.0)
    # A Unity heading (sin yaw, cos yaw) on the floor must map to the ROS heading (cos, sin).
    for deg in (0, 30, 90, 135, 200, 330):
        ux, uz = math.sin(math.radians(deg)), math.cos(math.radians(deg))
        rx, ry = coordinate_frames.unity_floor_to_ros(ux, uz)
        yaw = coordinate_frames.unity_yaw_to_ros(deg)
        assert (rx, ry) == pytest.approx((math.cos(yaw), math.sin(yaw)))


def test_no_negative_zero() -> None:
    assert math.copysign(1.0, coordinate_frames.unity_to_ros((0.0, 0.0, 0.0))[1]) == 1.0
    assert math.copysign(1.0, coordinate_frames.unity_yaw_to_ros(0.0)) == 1.0
