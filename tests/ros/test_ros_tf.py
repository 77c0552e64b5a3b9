"""The TF buffer: chains, interpolation, no extrapolation, and the optical frame's rotation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from objsearch.agent.camera_frames import camera_to_map
from objsearch.agent.geometry import Pose
from objsearch.ros.builder import OPTICAL_ROTATION
from objsearch.ros.errors import TransformError
from objsearch.ros.tf import TransformBuffer, quaternion_matrix

ZERO = np.zeros(3)
IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def yaw_q(yaw: float) -> np.ndarray:
    return np.array([0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)])


def robot(pitch: float = 0.0) -> TransformBuffer:
    tf = TransformBuffer()
    tilt = np.array([0.0, math.sin(pitch / 2), 0.0, math.cos(pitch / 2)])
    tf.add("base_link", "camera_link", 0, np.array([0.0, 0.0, 1.0]), tilt, static=True)
    tf.add("camera_link", "optical", 0, ZERO, np.array(OPTICAL_ROTATION), static=True)
    tf.add("map", "odom", 100, ZERO, IDENTITY)
    tf.add("map", "odom", 300, ZERO, IDENTITY)
    tf.add("odom", "base_link", 100, np.array([1.0, 2.0, 0.0]), yaw_q(0.0))
    tf.add("odom", "base_link", 300, np.array([3.0, 2.0, 0.0]), yaw_q(math.pi / 2))
    return tf


@pytest.mark.parametrize("pitch", [0.0, 0.3])
def test_the_optical_chain_is_the_renderers_camera_pose(pitch: float) -> None:
    tf = robot(pitch)
    got = tf.lookup("map", "optical", 100)
    np.testing.assert_allclose(got, camera_to_map(Pose(1.0, 2.0, 0.0), pitch=pitch), atol=1e-12)
    # Optical z is the camera's forward direction, optical y points down.
    np.testing.assert_allclose(quaternion_matrix(np.array(OPTICAL_ROTATION))[:, 2], [1, 0, 0])
    np.testing.assert_allclose(quaternion_matrix(np.array(OPTICAL_ROTATION))[:, 1], [0, 0, -1])


def test_between_samples_translation_is_linear_and_rotation_is_slerped() -> None:
    got = robot().lookup("map", "base_link", 200)
    np.testing.assert_allclose(got[:3, 3], [2.0, 2.0, 0.0])
    np.testing.assert_allclose(got[:3, :3], quaternion_matrix(yaw_q(math.pi / 4)), atol=1e-12)
    assert robot().latest_ns == 300


def test_no_extrapolation_and_unconnected_frames_are_named() -> None:
    tf = robot()
    with pytest.raises(TransformError, match="after the last"):
        tf.lookup("map", "optical", 301)
    with pytest.raises(TransformError, match="before the first"):
        tf.lookup("map", "optical", 99)
    with pytest.raises(TransformError, match=r"laser.*no parent"):
        tf.lookup("map", "laser", 200)
    with pytest.raises(TransformError, match="not a rigid transform"):
        tf.add("map", "odom", 400, ZERO, np.array([0.0, 0.0, 0.0, 2.0]))
