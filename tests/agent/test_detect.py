"""Detectors: the simulator's ground-truth masks and a TorchScript model the test builds."""

# No `from __future__ import annotations`: TorchScript reads the models' annotations at runtime.

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from objsearch.agent.camera_frames import CameraIntrinsics, GroundTruth, RGBDFrame, camera_to_map
from objsearch.agent.categories import Vocabulary
from objsearch.agent.detect import (
    CLASS_NAMES_FILE,
    DetectorError,
    GroundTruthDetector,
    MaskDetection,
    TorchDetector,
    accepted,
)
from objsearch.agent.geometry import Pose

K = CameraIntrinsics.from_hfov(32, 24, math.pi / 2)


class ColourSegmenter(torch.nn.Module):
    """Labels pixels by colour: red → label 0, green → label 1, blue → label 2 (never drawn)."""

    class_names: list[str]

    def __init__(self, class_names: list[str]) -> None:
        super().__init__()
        self.class_names = class_names

    def forward(self, image: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        channel = image.argmax(dim=0)
        bright = image.max(dim=0).values > 0.5
        masks = torch.stack([(channel == c) & bright for c in range(3)])
        keep = masks.flatten(1).any(dim=1)
        labels = torch.arange(3, dtype=torch.int64)[keep]
        scores = torch.full_like(labels, 9, dtype=torch.float32) / 10
        return masks[keep], labels, scores


def frame(rgb: np.ndarray, truth: GroundTruth | None = None) -> RGBDFrame:
    depth = np.ones(K.shape, np.float32)
    return RGBDFrame(rgb, depth, K, camera_to_map(Pose(0, 0, 0)), 0, truth)


def two_patches() -> np.ndarray:
    rgb = np.zeros((*K.shape, 3), np.uint8)
    rgb[2:8, 2:12, 0] = 255  # 60 red pixels
    rgb[10:20, 15:30, 1] = 255  # 150 green pixels
    return rgb


@pytest.fixture
def vocab() -> Vocabulary:
    return Vocabulary.load()


# torch 2.13 deprecates TorchScript; deployed detectors still come as TorchScript, so it is read.
pytestmark = pytest.mark.filterwarnings("ignore:`torch.jit.*deprecated:DeprecationWarning")


def save(model: torch.nn.Module, path: Path, how: str, names: list[str] | None = None) -> Path:
    if how == "export":
        program = torch.export.export(model, (torch.zeros(3, *K.shape),))
        extra = {CLASS_NAMES_FILE: json.dumps(names)} if names is not None else None
        torch.export.save(program, path, extra_files=extra)
    elif how == "script":
        torch.jit.script(model).save(str(path))  # type: ignore[no-untyped-call]
    else:
        torch.jit.trace(model, torch.zeros(3, *K.shape)).save(str(path))  # type: ignore[no-untyped-call]
    return path


@pytest.mark.parametrize("how", ["export", "script", "trace"])
def test_model_round_trip(tmp_path: Path, vocab: Vocabulary, how: str) -> None:
    # An export carries its names in an extra file and a scripted module as an attribute; a
    # traced one loses the attribute, so the names are passed.
    classes = ["Apple", "fridge", "Person"]
    path = save(ColourSegmenter(classes), tmp_path / "m.pt2", how, classes)
    names = classes if how == "trace" else None
    det = TorchDetector(path, vocab, class_names=names, device="cpu")
    rgb = two_patches()
    out = det.detect(frame(rgb))
    assert [d.cls for d in out] == ["Apple", "Fridge"]  # names resolve through the vocabulary
    np.testing.assert_array_equal(out[0].mask, rgb[..., 0] == 255)
    assert (out[0].area, out[1].area) == (60, 150)
    assert out[0].score == pytest.approx(0.9)
    # Per-class thresholds: 100 px for Apple (data/vocabulary.json).
    assert not accepted(out[0], vocab)
    assert accepted(MaskDetection("Apple", np.ones(K.shape, bool), 1.0), vocab)


def test_labels_outside_the_vocabulary_and_low_scores_are_dropped(
    tmp_path: Path, vocab: Vocabulary
) -> None:
    path = save(ColourSegmenter(["toaster", "Sofa", "Bed"]), tmp_path / "m.pt", "script")
    assert [d.cls for d in TorchDetector(path, vocab).detect(frame(two_patches()))] == ["Sofa"]
    strict = TorchDetector(path, vocab, score_threshold=0.95)
    assert strict.detect(frame(two_patches())) == ()


def test_bad_model_files_are_clear_errors(tmp_path: Path, vocab: Vocabulary) -> None:
    with pytest.raises(DetectorError, match="no detector model"):
        TorchDetector(tmp_path / "missing.pt", vocab)
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a model")
    with pytest.raises(DetectorError, match=r"neither a torch\.export program nor a TorchScript"):
        TorchDetector(junk, vocab)
    nameless = save(ColourSegmenter(["Apple", "Sofa", "Bed"]), tmp_path / "n.pt2", "export")
    with pytest.raises(DetectorError, match="class_names"):
        TorchDetector(nameless, vocab)
    assert TorchDetector(nameless, vocab, class_names=["Apple", "Sofa", "Bed"]).labels[0] == "Apple"
    traced = save(ColourSegmenter(["Apple", "Sofa", "Bed"]), tmp_path / "t.pt", "trace")
    with pytest.raises(DetectorError, match="class_names"):
        TorchDetector(traced, vocab)


class WrongShape(torch.nn.Module):
    class_names: list[str]

    def __init__(self) -> None:
        super().__init__()
        self.class_names = ["Apple"]

    def forward(self, image: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        return image[:1, :4, :4], torch.zeros(1, dtype=torch.int64), torch.ones(1)


def test_a_model_returning_the_wrong_shapes_is_reported(tmp_path: Path, vocab: Vocabulary) -> None:
    path = tmp_path / "w.pt"
    torch.jit.script(WrongShape()).save(str(path))  # type: ignore[no-untyped-call]
    with pytest.raises(DetectorError, match="expected"):
        TorchDetector(path, vocab).detect(frame(two_patches()))


def test_ground_truth_detector_reads_the_simulators_masks() -> None:
    instance = np.full(K.shape, -1, np.int32)
    instance[:5] = 0
    instance[5:7, :3] = 1
    truth = GroundTruth(instance, ("kitchen/Fridge|1", "kitchen/Apple|2"), ("Fridge", "Apple"))
    rgb = np.zeros((*K.shape, 3), np.uint8)
    dets = GroundTruthDetector().detect(frame(rgb, truth))
    assert [(d.cls, d.instance_id, d.area) for d in dets] == [
        ("Fridge", "kitchen/Fridge|1", 5 * 32),
        ("Apple", "kitchen/Apple|2", 6),
    ]
    only = GroundTruthDetector(frozenset({"Apple"})).detect(frame(rgb, truth))
    assert [d.cls for d in only] == ["Apple"]
    with pytest.raises(DetectorError, match="no ground truth"):
        GroundTruthDetector().detect(frame(rgb))


def test_a_rendered_target_is_located_and_approached() -> None:
    from objsearch.agent.detect import approach, locate
    from objsearch.agent.session import load_context
    from objsearch.sim.placements import base_placements, table1_removals
    from objsearch.sim.render import SimulatedCamera

    ctx = load_context("paper")
    placements = base_placements(ctx.home, table1_removals(ctx.home))
    laptop = next(p for p in placements.values() if p.cls == "Laptop")
    truth_vp = ctx.navmap.nearest_viewpoint(laptop.box.center[0], laptop.box.center[1], "bedroom")
    camera = SimulatedCamera(ctx.home, placements)
    cx, cy = laptop.box.center[0], laptop.box.center[1]
    # From the nearest viewpoint a level camera 1 m up looks over the laptop; step back until
    # the laptop is in view with a mask above the threshold.
    det = None
    for vp in sorted(
        ctx.navmap.viewpoints("bedroom"), key=lambda v: (math.hypot(v.x - cx, v.y - cy), v)
    ):
        frame_ = camera.frame(Pose(vp.x, vp.y, math.atan2(cy - vp.y, cx - vp.x)), "bedroom")
        det = next((d for d in GroundTruthDetector().detect(frame_) if d.cls == "Laptop"), None)
        if det is not None and det.area >= 100:
            break
    assert det is not None
    where = locate(frame_, det)
    assert where is not None
    # The seen surface's centre of mass lies within the laptop's box (inflated by a few mm).
    box = laptop.box
    assert all(
        abs(w - c) <= s / 2 + 5e-3 for w, c, s in zip(where, box.center, box.size, strict=True)
    )
    pose = approach(ctx.navmap, "bedroom", where)
    assert (
        math.hypot(pose.x - truth_vp.x, pose.y - truth_vp.y) <= 0.36
    )  # the same or next viewpoint
    empty = MaskDetection("Laptop", np.zeros(frame_.intrinsics.shape, bool), 1.0)
    assert locate(frame_, empty) is None
