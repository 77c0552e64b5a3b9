"""Instance masks from a camera frame: the ``Detector`` seam and its two implementations.

- :class:`GroundTruthDetector` reads the simulator's per-pixel ground truth (the paper's simulator
  hands over "the object category and mask", §6.1);
- :class:`TorchDetector` runs a trained model (the robot's Mask R-CNN, §4.3): a ``torch.export``
  program (``.pt2``) or a scripted or traced TorchScript module.

A detection is located by back-projecting its mask (:func:`locate`), and approached from its
nearest viewpoint (:func:`approach`). Masks become detections the agent accepts only when their area reaches the class's
``min_mask_area_px`` (paper §5.2, ``data/vocabulary.json``): :func:`accepted`.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from objsearch.agent.camera_frames import BoolArray, RGBDFrame
from objsearch.agent.categories import Vocabulary
from objsearch.agent.errors import ObjsearchError, UnknownObjectClassError
from objsearch.agent.geometry import Point, Pose, heading
from objsearch.agent.navmap import NavigationMap

if TYPE_CHECKING:
    import torch


class DetectorError(ObjsearchError, ValueError):
    """A detector cannot be loaded or returned something that is not masks and labels."""


@dataclass(frozen=True, slots=True, eq=False)
class MaskDetection:
    cls: str  # a class of the vocabulary
    mask: BoolArray  # (H, W)
    score: float
    instance_id: str | None = None  # known only in simulation

    @property
    def area(self) -> int:
        return int(np.count_nonzero(self.mask))


class Detector(Protocol):
    def detect(self, frame: RGBDFrame) -> tuple[MaskDetection, ...]: ...


def accepted(det: MaskDetection, vocabulary: Vocabulary) -> bool:
    """Whether a mask is large enough to count as seeing its object (its class's threshold)."""
    oc = vocabulary.classes.get(det.cls)
    return oc is not None and det.area >= oc.min_mask_area_px


class GroundTruthDetector:
    """One mask per object visible in a simulated frame, labelled with its class and instance."""

    def __init__(self, classes: set[str] | frozenset[str] | None = None) -> None:
        self.classes = classes  # None: every object class in the frame

    def detect(self, frame: RGBDFrame) -> tuple[MaskDetection, ...]:
        truth = frame.truth
        if truth is None:
            raise DetectorError(
                "this frame has no ground truth (it did not come from the simulator); "
                "use a model detector"
            )
        present = np.unique(truth.instance)
        out = []
        for k in present[present >= 0]:
            cls = truth.classes[int(k)]
            if self.classes is not None and cls not in self.classes:
                continue
            out.append(MaskDetection(cls, truth.instance == k, 1.0, truth.ids[int(k)]))
        return tuple(out)


class TorchDetector:
    """An instance-segmentation model saved with ``torch.export`` (``.pt2``) or TorchScript.

    Contract (what exporting, scripting or tracing a Mask R-CNN wrapper gives): ``forward`` takes
    a float image (3, H, W) in [0, 1] and returns ``(masks, labels, scores)`` — masks (N, H, W),
    boolean or probabilities (thresholded at 0.5), labels (N,) int64 indices into the model's
    class names, scores (N,). Class names come from ``class_names=``, else from the file: a
    ``class_names.json`` extra file of a ``.pt2`` (``torch.export.save(..., extra_files=...)``) or a
    ``class_names: List[str]`` attribute of a TorchScript module. Names are resolved through the
    vocabulary (class names, aliases and AI2-THOR types) and labels of other classes are dropped.
    ``torch.export`` is the format to prefer: torch 2.13 deprecates TorchScript, which is still read
    because that is what many deployed detectors are.
    """

    def __init__(
        self,
        path: str | Path,
        vocabulary: Vocabulary,
        *,
        class_names: list[str] | None = None,
        score_threshold: float = 0.5,
        device: str | None = None,
    ) -> None:
        import torch

        self.device = torch.device(device or ("cuda" if torch.cuda.is_available() else "cpu"))
        path = Path(path)
        if not path.is_file():
            raise DetectorError(f"no detector model at {path}")
        self.path = path
        if zipfile.is_zipfile(path) and _is_exported_program(path):
            self.model, stored = self._load_exported(path)
        else:
            self.model, stored = self._load_torchscript(path)
        names = class_names if class_names is not None else stored
        if names is None:
            raise DetectorError(
                f"{path} has no class_names attribute; pass the model's class names"
            )
        self.labels: list[str | None] = []
        for name in names:
            try:
                self.labels.append(vocabulary.resolve(name).name)
            except UnknownObjectClassError:
                self.labels.append(None)
        self.score_threshold = score_threshold

    def _load_exported(self, path: Path) -> tuple[Any, list[str] | None]:
        import torch

        extra = {CLASS_NAMES_FILE: ""}
        try:
            program = torch.export.load(path, extra_files=extra)
        except (RuntimeError, ValueError, KeyError) as exc:
            raise DetectorError(
                f"{path} is not a torch.export program: {_first_line(exc)}"
            ) from None
        names: list[str] | None = None
        if extra[CLASS_NAMES_FILE]:
            try:
                loaded = json.loads(extra[CLASS_NAMES_FILE])
            except ValueError as exc:
                raise DetectorError(f"{path}: {CLASS_NAMES_FILE} is not JSON: {exc}") from None
            if not (isinstance(loaded, list) and all(isinstance(n, str) for n in loaded)):
                raise DetectorError(f"{path}: {CLASS_NAMES_FILE} must be a list of strings")
            names = loaded
        return program.module().to(self.device), names

    def _load_torchscript(self, path: Path) -> tuple[Any, list[str] | None]:
        import torch

        try:
            model = torch.jit.load(  # type: ignore[no-untyped-call]
                str(path), map_location=self.device
            ).eval()
        except (RuntimeError, ValueError) as exc:
            raise DetectorError(
                f"{path} is neither a torch.export program nor a TorchScript model: "
                f"{_first_line(exc)}"
            ) from None
        return model, _attr_names(model)

    def detect(self, frame: RGBDFrame) -> tuple[MaskDetection, ...]:
        import torch

        image = torch.from_numpy(np.ascontiguousarray(frame.rgb)).to(self.device)
        image = image.permute(2, 0, 1).float().div_(255.0)
        with torch.inference_mode():
            try:
                out = self.model(image)
            except RuntimeError as exc:
                raise DetectorError(f"{self.path} failed on a frame: {exc}") from None
        masks, labels, scores = self._check(out, frame.intrinsics.shape)
        dets = []
        for i in range(int(labels.shape[0])):
            label = int(labels[i])
            cls = self.labels[label] if 0 <= label < len(self.labels) else None
            if cls is None or float(scores[i]) < self.score_threshold:
                continue
            dets.append(MaskDetection(cls, masks[i], float(scores[i])))
        return tuple(dets)

    def _check(
        self, out: Any, shape: tuple[int, int]
    ) -> tuple[BoolArray, np.ndarray[Any, Any], np.ndarray[Any, Any]]:
        import torch

        if not (isinstance(out, tuple | list) and len(out) == 3):
            raise DetectorError(
                f"{self.path} must return (masks, labels, scores), not {type(out).__name__}"
            )
        masks_t, labels_t, scores_t = out
        if not all(isinstance(t, torch.Tensor) for t in out):
            raise DetectorError(f"{self.path} must return three tensors")
        n = int(labels_t.shape[0]) if labels_t.dim() == 1 else -1
        if masks_t.dim() == 4 and masks_t.shape[1] == 1:  # torchvision's (N, 1, H, W)
            masks_t = masks_t[:, 0]
        if n < 0 or tuple(masks_t.shape) != (n, *shape) or tuple(scores_t.shape) != (n,):
            raise DetectorError(
                f"{self.path} returned masks {tuple(masks_t.shape)}, labels "
                f"{tuple(labels_t.shape)}, scores {tuple(scores_t.shape)}; expected (N, {shape[0]}, "
                f"{shape[1]}), (N,), (N,)"
            )
        masks_b = masks_t if masks_t.dtype == torch.bool else masks_t >= 0.5
        return (
            masks_b.cpu().numpy(),
            labels_t.to(torch.int64).cpu().numpy(),
            scores_t.float().cpu().numpy(),
        )


#: The extra file of a ``.pt2`` that names the model's labels, in order (a JSON list of strings).
CLASS_NAMES_FILE = "class_names.json"


def _is_exported_program(path: Path) -> bool:
    # Both formats are zip files, so look inside rather than trust the suffix: a torch.export
    # archive says so in its ``archive_format`` entry; TorchScript has none.
    with zipfile.ZipFile(path) as archive:
        marks = [n for n in archive.namelist() if n.rpartition("/")[2] == "archive_format"]
        return any(archive.read(n).strip() == b"pt2" for n in marks)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _attr_names(model: torch.jit.ScriptModule) -> list[str] | None:
    names = getattr(model, "class_names", None)
    if isinstance(names, list | tuple) and all(isinstance(n, str) for n in names):
        return [str(n) for n in names]
    return None


def locate(frame: RGBDFrame, det: MaskDetection) -> tuple[float, float, float] | None:
    """Local 3-D reconstruction of one detection (§5.1): the centre of mass of its mask's
    back-projected depth, map frame; None when no pixel of the mask has depth."""
    from objsearch.agent.camera_frames import backproject

    points = backproject(frame, det.mask)
    if len(points) == 0:
        return None
    c = points.astype(np.float64).mean(axis=0)
    return (float(c[0]), float(c[1]), float(c[2]))


def approach(navmap: NavigationMap, room: str, position: tuple[float, float, float]) -> Pose:
    """Where to stand to face a located object: its nearest viewpoint, heading towards it."""
    vp = navmap.nearest_viewpoint(position[0], position[1], room)
    return Pose(vp.x, vp.y, heading(vp, Point(position[0], position[1])))
