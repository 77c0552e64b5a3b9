"""RGB-D in bags: a mapping sweep recorded in each format builds the simulator's map, to the bit.

One room (the bathroom) and one sampling point keep it small: 8 views, ~22 MB a bag.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from objsearch.agent.camera_frames import DEFAULT_INTRINSICS
from objsearch.agent.categories import Category
from objsearch.agent.detect import GroundTruthDetector
from objsearch.agent.mapping import (
    BuiltMap,
    MappingConfig,
    SemanticMapBuilder,
    detected,
    survey_poses,
)
from objsearch.agent.session import HomeContext, load_context
from objsearch.cli import main
from objsearch.pipeline.bags.errors import BagError
from objsearch.pipeline.bags.formats import BagFormat
from objsearch.pipeline.bags.read import read_bag
from objsearch.pipeline.bags.record import record_mapping_sweep, sweep_messages, write_bag
from objsearch.pipeline.bags.rgbd import build_map_from_bag
from objsearch.ros.images import decode_image, intrinsics_of
from objsearch.ros.topics import Role, TopicMap
from objsearch.ros.types import typestore
from objsearch.sim.placements import base_placements, table1_removals
from objsearch.sim.render import SimulatedCamera, SurveyFrames

ROOMS = ["bathroom"]
CPU = torch.device("cpu")
#: Fused on one thread, as the CLI does (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("one_torch_thread")
CONFIG = MappingConfig(points_per_room=1)


def bag_name(fmt: BagFormat, stem: str) -> str:
    return f"{stem}.bag" if fmt is BagFormat.ROS1 else stem


@pytest.fixture(scope="module")
def ctx() -> HomeContext:
    return load_context("paper")


def camera(ctx: HomeContext) -> SimulatedCamera:
    return SimulatedCamera(ctx.home, base_placements(ctx.home, table1_removals(ctx.home)))


def statics(ctx: HomeContext) -> tuple[str, ...]:
    return ctx.vocabulary.names(Category.STATIC)


@pytest.fixture(scope="module")
def sim_map(ctx: HomeContext) -> BuiltMap:
    """What ``objsearch map build`` makes of the same views rendered directly."""
    builder = SemanticMapBuilder(ctx.navmap, statics(ctx), CONFIG, device=CPU)
    frames = SurveyFrames(camera(ctx), survey_poses(ctx.navmap, ROOMS, 1)).frames()
    builder.fuse(detected(frames, GroundTruthDetector(frozenset(statics(ctx)))))
    return builder.build()


@pytest.fixture(scope="module", params=[f.value for f in BagFormat])
def sweep(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    fmt = BagFormat(request.param)
    out = tmp_path_factory.mktemp(f"sweep-{fmt.value}") / bag_name(fmt, "sweep")
    record_mapping_sweep(out, fmt, rooms=ROOMS, points_per_room=1, chunk_bytes=1 << 20)
    return out


def test_map_from_the_bag_is_the_simulators(
    sweep: Path, sim_map: BuiltMap, ctx: HomeContext
) -> None:
    built, report = build_map_from_bag(sweep, ctx.navmap, statics(ctx), CONFIG, device=CPU)
    assert report.reader == "AnyReader" and report.views == 8
    assert not report.skipped and not report.rejected and not report.losses
    assert len(sim_map.instances) >= 4
    # Same depth, masks, intrinsics and (through TF, interpolated) camera poses → the same voxels.
    assert built.points == sim_map.points
    assert built.instances == sim_map.instances
    assert built.semmap == sim_map.semmap


def test_sweep_images_and_camera_info_are_the_rendered_ones(sweep: Path, ctx: HomeContext) -> None:
    from rosbags.highlevel import AnyReader

    fmt = BagFormat.ROS1 if sweep.suffix == ".bag" else BagFormat.ROS2_MCAP
    room, pose = survey_poses(ctx.navmap, ROOMS, 1)[0]
    frame = camera(ctx).frame(pose, room)
    first: dict[str, Any] = {}
    with AnyReader([sweep], default_typestore=typestore(fmt.distro)) as reader:
        for conn, _, raw in reader.messages():
            if conn.topic not in first and "camera" in conn.topic:
                first[conn.topic] = reader.deserialize(raw, conn.msgtype)
    rgb, depth = first["/camera/color/image_raw"], first["/camera/depth/image_raw"]
    inst = first["/camera/instances/image_raw"]
    assert (rgb.encoding, depth.encoding, inst.encoding) == ("rgb8", "32FC1", "mono16")
    assert rgb.header.frame_id == depth.header.frame_id == "camera_link_optical"
    np.testing.assert_array_equal(decode_image(rgb), frame.rgb)
    np.testing.assert_array_equal(decode_image(depth), frame.depth)
    assert frame.truth is not None
    np.testing.assert_array_equal(decode_image(inst) > 0, frame.truth.instance >= 0)
    assert intrinsics_of(first["/camera/color/camera_info"]) == (DEFAULT_INTRINSICS, False)


def test_ingest_counts_the_image_topics_and_keeps_the_detections(sweep: Path) -> None:
    contents = read_bag(sweep)
    roles = {t.topic: t.role for t in contents.report.topics}
    for topic in (
        "/camera/color/image_raw",
        "/camera/depth/image_raw",
        "/camera/instances/image_raw",
    ):
        assert roles[topic].endswith("(counted, not converted)")
    rows = {t.topic: t for t in contents.report.topics}
    assert rows["/camera/depth/image_raw"].messages == 8
    assert contents.report.event_types["objects_detected"] == 8
    assert not contents.report.damaged


def _filtered(tmp: Path, ctx: HomeContext, drop: set[Role]) -> Path:
    """A two-view MCAP sweep without the given roles' topics."""
    fmt = BagFormat.ROS2_MCAP
    messages = sweep_messages(
        camera(ctx),
        survey_poses(ctx.navmap, ROOMS, 1)[:2],
        GroundTruthDetector(),
        fmt.distro,
        TopicMap(),
    )
    out = tmp / "partial"
    write_bag(out, fmt, (m for m in messages if m[1] not in drop), TopicMap())
    return out


@pytest.mark.parametrize(
    ("drop", "named"),
    [
        ({Role.IMAGE, Role.DEPTH, Role.INSTANCES}, ["no depth images", "no instance images"]),
        ({Role.TF, Role.TF_STATIC}, ["no TF (TFMessage or tfMessage on /tf"]),
        ({Role.CAMERA_INFO}, ["no camera info (CameraInfo on /camera/color/camera_info"]),
        ({Role.TF_STATIC}, ["TF: no transform from camera_link_optical to map"]),
    ],
)
def test_a_bag_lacking_a_part_is_refused_naming_it(
    tmp_path: Path, ctx: HomeContext, drop: set[Role], named: list[str]
) -> None:
    bag = _filtered(tmp_path, ctx, drop)
    with pytest.raises(BagError) as err:
        build_map_from_bag(bag, ctx.navmap, statics(ctx), CONFIG, device=CPU)
    for text in named:
        assert text in str(err.value)


@pytest.fixture(scope="module")
def ros1_sweep(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("sweep-cut") / "sweep.bag"
    record_mapping_sweep(out, BagFormat.ROS1, rooms=ROOMS, points_per_room=1)
    return out


def _cut(src: Path, dst: Path, fraction: float) -> Path:
    data = src.read_bytes()
    dst.write_bytes(data[: int(len(data) * fraction)])
    return dst


def test_a_cut_bag_builds_from_what_is_readable_and_says_so(
    ros1_sweep: Path, tmp_path: Path, ctx: HomeContext, capsys: pytest.CaptureFixture[str]
) -> None:
    cut = _cut(ros1_sweep, tmp_path / "cut.bag", 0.6)
    built, report = build_map_from_bag(cut, ctx.navmap, statics(ctx), CONFIG, device=CPU)
    assert report.reader == "salvage scan"
    assert 0 < report.views < 8 and report.losses
    assert built.frames == report.views and built.instances
    assert main(["map", "build", "--bag", str(cut), "--no-search"]) == 0
    out = capsys.readouterr().out
    assert "salvage scan" in out and "LOST" in out


def test_cli_records_a_sweep_and_builds_from_it(
    tmp_path: Path, sim_map: BuiltMap, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "sweep"
    args = ["--out", str(bag), "--bag-format", "ros2-sqlite3", "--rooms", "bathroom"]
    assert main(["record", "--mapping-sweep", *args, "--points-per-room", "1"]) == 0
    assert "mapping sweep" in capsys.readouterr().out
    out_map = tmp_path / "map.json"
    code = main(
        [
            "map",
            "build",
            "--bag",
            str(bag),
            "--out",
            str(out_map),
            "--no-search",
            "--format",
            "json",
        ]
    )
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert report["bag"]["views"] == 8 and report["frames"] == 8
    assert json.loads(out_map.read_text()) == json.loads(json.dumps(sim_map.semmap.to_json()))


def test_cli_refuses_bad_combinations(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["map", "build", "--bag", str(tmp_path / "nope.bag"), "--no-search"]) == 2
    assert "nope.bag" in capsys.readouterr().err
    (tmp_path / "x.bag").write_bytes(b"")
    (tmp_path / "m.pt").write_bytes(b"")
    assert (
        main(["map", "build", "--bag", str(tmp_path / "x.bag"), "--model", str(tmp_path / "m.pt")])
        == 2
    )
    assert "--model" in capsys.readouterr().err
    bag = str(tmp_path / "s.bag")
    assert (
        main(
            ["record", "--mapping-sweep", "--out", bag, "--bag-format", "ros1", "--targets", "Cup"]
        )
        == 2
    )
    assert "--targets" in capsys.readouterr().err
    assert (
        main(
            ["record", "--mapping-sweep", "--out", bag, "--bag-format", "ros1", "--rooms", "attic"]
        )
        == 2
    )
    assert "attic" in capsys.readouterr().err
