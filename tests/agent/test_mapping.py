"""Semantic map building: back-projection, voxel fusion, instances, and the paper home end to end."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from objsearch.agent.camera_frames import backproject
from objsearch.agent.categories import Category
from objsearch.agent.detect import GroundTruthDetector
from objsearch.agent.geometry import Pose
from objsearch.agent.mapping import (
    BuiltMap,
    GridSpec,
    MappingConfig,
    SemanticMapBuilder,
    VoxelGrid,
    backproject_labels,
    detected,
    label_image,
    sampling_points,
    survey_poses,
)
from objsearch.agent.semmap import SemanticMap
from objsearch.agent.session import load_context
from objsearch.sim.mapeval import compare
from objsearch.sim.render import SimulatedCamera, SurveyFrames

CPU = torch.device("cpu")


#: Fused on one thread, as the CLI does (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_the_single_sampling_point_is_the_rooms_door() -> None:
    # The home data derives each door with the paper's rule from the raw grid (pipeline/navgrid);
    # the mapper derives it again from the navigation map alone.
    ctx = load_context("paper")
    for room in ctx.home.rooms:
        assert sampling_points(ctx.navmap, room.name) == (room.door,)
        four = sampling_points(ctx.navmap, room.name, 4)
        assert len(set(four)) == 4 and set(four) <= set(room.viewpoints)
    poses = survey_poses(ctx.navmap, ["kitchen"], 1)
    assert [round(math.degrees(p.yaw)) for _, p in poses] == [0, 45, 90, 135, 180, 225, 270, 315]


def test_torch_back_projection_matches_the_numpy_one() -> None:
    ctx = load_context("paper")
    door = ctx.home.room("bedroom").door
    frame = SimulatedCamera(ctx.home).frame(Pose(door.x, door.y, 2.0), "bedroom")
    assert frame.truth is not None
    mask = frame.truth.instance >= 0
    labels = np.where(mask, 3, -1)
    points, lab = backproject_labels(
        torch.from_numpy(frame.depth),
        torch.from_numpy(labels),
        torch.from_numpy(frame.intrinsics.rays().copy()),
        torch.from_numpy(frame.T_map_camera.astype(np.float32)),
    )
    expected = backproject(frame, mask)
    assert points.shape == expected.shape and int(mask.sum()) > 1000
    np.testing.assert_allclose(points.numpy(), expected, atol=1e-4)
    assert (lab == 3).all()


def test_voxel_votes_and_the_winning_class() -> None:
    spec = GridSpec((0.0, 0.0, 0.0), (4, 4, 4), 0.5)
    grid = VoxelGrid(spec, n_classes=3, device=CPU)
    pts = torch.tensor(
        [[0.1, 0.1, 0.1], [0.2, 0.3, 0.4], [0.1, 0.1, 0.1], [1.9, 1.9, 1.9], [2.1, 0, 0]]
    )
    added = grid.integrate(pts, torch.tensor([2, 1, 2, 0, 0]))
    assert added == 4  # the last point is outside the 2 m grid
    labels = grid.labels()
    assert labels[0, 0, 0] == 2 and labels[3, 3, 3] == 0
    assert (labels >= 0).sum() == 2
    assert (grid.labels(min_votes=3) >= 0).sum() == 1  # three points in voxel (0, 0, 0)
    np.testing.assert_allclose(spec.centre(np.array([[1, 2, 3]])), [[0.75, 1.25, 1.75]])


def test_label_image_prefers_the_higher_score() -> None:
    from objsearch.agent.detect import MaskDetection

    a = np.zeros((2, 2), bool)
    a[0] = True
    b = np.ones((2, 2), bool)
    dets = [MaskDetection("Sofa", a, 0.9), MaskDetection("Bed", b, 0.5), MaskDetection("Cat", b, 1)]
    np.testing.assert_array_equal(label_image(dets, ["Bed", "Sofa"], (2, 2)), [[1, 1], [0, 0]])


def build(rooms: list[str], k: int) -> BuiltMap:
    ctx = load_context("paper")
    classes = ctx.vocabulary.names(Category.STATIC)
    builder = SemanticMapBuilder(ctx.navmap, classes, MappingConfig(points_per_room=k), device=CPU)
    frames = SurveyFrames(SimulatedCamera(ctx.home), survey_poses(ctx.navmap, rooms, k))
    builder.fuse(detected(frames.frames(), GroundTruthDetector(frozenset(classes))))
    return builder.build()


@pytest.fixture(scope="module")
def paper_map() -> BuiltMap:
    return build([r.name for r in load_context("paper").home.rooms], 4)


def test_built_map_of_the_paper_home_is_close_to_the_truth(paper_map: BuiltMap) -> None:
    truth = load_context("paper").semmap
    acc = compare(truth, paper_map.semmap)
    summary = acc.summary()
    # One miss: the kitchen sink basin lies under the counter top's box, invisible from 1 m up.
    assert acc.missed == ("kitchen/Sink|+00.00|+00.89|-01.44|SinkBasin",)
    assert summary["spurious"] == 0
    assert summary["median_error_m"] < 0.3
    assert summary["max_error_m"] < 0.75
    for s in paper_map.semmap.statics:
        assert s.container == (s.cls in {"Fridge", "Microwave"})
        assert s.viewpoint == load_context("paper").navmap.nearest_viewpoint(
            s.loc.x, s.loc.y, s.room
        )


def test_built_map_json_round_trip(paper_map: BuiltMap) -> None:
    doc = paper_map.semmap.to_json()
    assert SemanticMap.from_json(doc) == paper_map.semmap


def test_same_frames_give_the_same_map() -> None:
    a, b = build(["bathroom"], 1), build(["bathroom"], 1)
    assert a == b and len(a.instances) >= 4
