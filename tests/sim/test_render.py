"""The ray-cast renderer against geometry worked out by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from objsearch.agent.camera_frames import (
    DEFAULT_INTRINSICS,
    CameraIntrinsics,
    backproject,
    camera_to_map,
    project,
)
from objsearch.agent.geometry import Pose
from objsearch.agent.home import Box, load_home
from objsearch.sim.render import (
    CEILING,
    FLOOR,
    NO_RETURN,
    WALL,
    Scene,
    SceneObject,
    SimulatedCamera,
    render,
)

K = CameraIntrinsics.from_hfov(64, 48, math.pi / 2)  # f = 32 px: small and fast
CENTRE = (23, 31)  # a pixel centre next to the optical axis (cx = 31.5, cy = 23.5)


def box_scene(*boxes: Box, half: float = 20.0) -> Scene:
    objects = tuple(SceneObject(f"b{i}", "Box", b) for i, b in enumerate(boxes))
    return Scene((-half, -half, 0.0), (half, half, 2.5), objects)


def test_depth_of_a_box_face_is_its_distance_along_the_optical_axis() -> None:
    box = Box((3.0, 0.0, 1.0), (2.0, 1.0, 1.0))  # near face at x = 2
    t = camera_to_map(Pose(0.0, 0.0, 0.0), height=1.0)
    out = render(box_scene(box), K, t)
    v, u = CENTRE
    assert out.instance[v, u] == 0
    assert out.depth[v, u] == pytest.approx(2.0, abs=1e-5)
    # Depth is z in the optical frame, not the ray length: constant over the flat face.
    face = out.instance == 0
    assert face.sum() > 50
    np.testing.assert_allclose(out.depth[face], 2.0, atol=1e-5)


def test_floor_and_walls_where_the_rays_meet_them() -> None:
    t = camera_to_map(Pose(0.0, 0.0, 0.0), height=1.0)
    out = render(box_scene(half=4.0), K, t)
    # Bottom row, v = 47: ray slope (47 − 23.5)/32 down; it meets the floor at depth 32/23.5.
    assert out.instance[47, 31] == FLOOR
    assert out.depth[47, 31] == pytest.approx(1.0 * 32 / 23.5, rel=1e-5)
    assert out.instance[0, 31] == CEILING  # 1.5 m above the camera: depth 1.5·32/23.5 < 4
    assert out.depth[0, 31] == pytest.approx(1.5 * 32 / 23.5, rel=1e-5)
    assert out.instance[CENTRE] == WALL
    assert out.depth[CENTRE] == pytest.approx(4.0, abs=1e-5)


def test_the_nearer_box_occludes_and_range_limits_returns() -> None:
    near = Box((2.5, 0.0, 1.0), (1.0, 0.4, 0.4))
    far = Box((5.0, 0.0, 1.0), (1.0, 3.0, 2.0))
    t = camera_to_map(Pose(0.0, 0.0, 0.0), height=1.0)
    out = render(box_scene(far, near, half=50.0), K, t, max_range=10.0)
    assert out.instance[CENTRE] == 1 and out.depth[CENTRE] == pytest.approx(2.0, abs=1e-5)
    assert (out.instance == 0).any()  # the far box shows around the near one
    assert out.instance[23, 0] == NO_RETURN and out.depth[23, 0] == 0.0  # the 50 m walls


def test_box_behind_the_camera_is_not_drawn_and_a_yaw_turns_the_view() -> None:
    box = Box((-3.0, 0.0, 1.0), (1.0, 1.0, 1.0))
    ahead = render(box_scene(box), K, camera_to_map(Pose(0.0, 0.0, 0.0)))
    assert not (ahead.instance == 0).any()
    behind = render(box_scene(box), K, camera_to_map(Pose(0.0, 0.0, math.pi)))
    assert behind.depth[CENTRE] == pytest.approx(2.5, abs=1e-5)


def test_camera_pose_is_a_rotation_and_pitch_looks_down() -> None:
    t = camera_to_map(Pose(1.0, 2.0, 0.7), height=1.2, pitch=0.3)
    r = t[:3, :3]
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    out = render(box_scene(), K, camera_to_map(Pose(0.0, 0.0, 0.0), height=1.0, pitch=math.pi / 4))
    # The centre ray at 45° down meets the floor 1 m ahead: depth √2 along the optical axis…
    # …minus the half-pixel offset of the pixel centre, so compare the back-projected point.
    frame_pts = backproject_one(out.depth, CENTRE, camera_to_map(Pose(0, 0, 0), pitch=math.pi / 4))
    assert frame_pts[2] == pytest.approx(0.0, abs=1e-5)
    assert frame_pts[0] == pytest.approx(1.0, abs=0.05)


def backproject_one(depth: np.ndarray, pixel: tuple[int, int], t: np.ndarray) -> np.ndarray:
    from objsearch.agent.camera_frames import RGBDFrame

    frame = RGBDFrame(np.zeros((*depth.shape, 3), np.uint8), depth, K, t)
    mask = np.zeros(depth.shape, bool)
    mask[pixel] = True
    return np.asarray(backproject(frame, mask)[0])


def test_back_projection_and_projection_round_trip_on_a_rendered_kitchen() -> None:
    home = load_home("paper")
    camera = SimulatedCamera(home)
    door = home.room("kitchen").door
    frame = camera.frame(Pose(door.x, door.y, math.pi), "kitchen")
    points = backproject(frame)
    valid = frame.depth > 0
    assert valid.all()  # walls everywhere within 10 m
    uv, z = project(points, frame.intrinsics, frame.T_map_camera)
    vv, uu = np.nonzero(valid)
    np.testing.assert_allclose(uv[:, 0], uu, atol=2e-3)
    np.testing.assert_allclose(uv[:, 1], vv, atol=2e-3)
    np.testing.assert_allclose(z, frame.depth[valid], rtol=1e-5)
    # Every pixel of an object lies on that object's box surface.
    truth = frame.truth
    assert truth is not None
    statics = home.statics
    shown = [k for k in np.unique(truth.instance) if k >= 0]
    assert shown, "the kitchen door looks at some furniture"
    for k in shown:
        pts = backproject(frame, truth.instance == k)
        box = statics[truth.ids[k]].box
        inflated = Box(box.center, tuple(s + 2e-3 for s in box.size))  # type: ignore[arg-type]
        assert max(inflated.distance_to(tuple(p)) for p in pts) == 0.0


def test_rendering_is_deterministic_and_an_opened_container_shows_its_inside() -> None:
    home = load_home("paper")
    camera = SimulatedCamera(home)
    fridge = next(s for s in home.room("kitchen").statics if s.cls == "Fridge")
    pose = Pose(2.0, 3.0, math.atan2(fridge.box.center[1] - 3.0, fridge.box.center[0] - 2.0))
    a = camera.frame(pose, "kitchen")
    b = camera.frame(pose, "kitchen")
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth, b.depth)
    k = a.truth.ids.index(fridge.id) if a.truth else -1
    assert a.truth is not None and (a.truth.instance == k).sum() > 1000
    opened = camera.frame(pose, "kitchen", opened=fridge.id)
    assert opened.truth is not None and fridge.id not in opened.truth.ids


def test_default_intrinsics_match_the_geometric_camera() -> None:
    from objsearch.sim.perception import Camera

    assert DEFAULT_INTRINSICS.fx == pytest.approx(Camera().focal_px)
    assert DEFAULT_INTRINSICS.shape == (480, 640)
