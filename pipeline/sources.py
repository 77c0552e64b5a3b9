"""Reading the raw public data under the shared source folder.

Every reader takes the source root and says what the file is needed for, so that a missing or
malformed file fails with a ``SourceDataError`` naming both.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from objsearch.agent.geometry import Vec3

from .errors import SourceDataError

ITHOR_SCENES = Path("ai2thor/ithor_scenes")
ALFRED_LAYOUTS = Path("ai2thor/alfred_layouts")
VG_MATRIX = Path("vg/VSGM/relationship_matrics_with_word.csv")
HOZ_ADJACENCY = Path("vg/HOZ/adjmat_83x83.csv")


@dataclass(frozen=True)
class ThorObject:
    """One object of an iTHOR scene, in the Unity frame as the metadata gives it."""

    object_id: str
    object_type: str
    aabb_center: Vec3
    aabb_size: Vec3
    pickupable: bool
    openable: bool
    parents: tuple[str, ...]
    # The object's own name (``Cup_dc95d5e8``), pivot position and yaw: what the rearrangement
    # episodes give for a pose, so their poses can be tied to this box.
    name: str = ""
    position: Vec3 | None = None
    yaw_deg: float = 0.0


@dataclass(frozen=True)
class ThorScene:
    name: str
    room_type: str
    floor_center: Vec3
    floor_size: Vec3
    objects: tuple[ThorObject, ...]
    path: Path


@dataclass(frozen=True)
class CooccurrenceMatrix:
    """Visual Genome image counts: ``count(a, b)`` images show both, ``count(a, a)`` show a."""

    names: tuple[str, ...]
    counts: tuple[tuple[int, ...], ...]
    path: Path

    def count(self, a: str, b: str) -> int:
        return self.counts[self.names.index(a)][self.names.index(b)]


def require(path: Path, needed_for: str) -> Path:
    if not path.is_file():
        raise SourceDataError(path, needed_for)
    return path


def scene_path(source: Path, floorplan: str) -> Path:
    return source / ITHOR_SCENES / f"{floorplan}.json"


def layout_path(source: Path, floorplan: str) -> Path:
    return source / ALFRED_LAYOUTS / f"{floorplan}-layout.npy"


def openable_path(source: Path, floorplan: str) -> Path:
    return source / ALFRED_LAYOUTS / f"{floorplan}-openable.json"


def _load_json(path: Path, needed_for: str) -> Any:
    require(path, needed_for)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SourceDataError(path, needed_for, f"unreadable JSON ({exc})") from exc


def _vec(raw: Any) -> Vec3:
    return (float(raw["x"]), float(raw["y"]), float(raw["z"]))


def load_scene(source: Path, floorplan: str, needed_for: str) -> ThorScene:
    path = scene_path(source, floorplan)
    raw = _load_json(path, needed_for)
    try:
        floor = raw["floor_aabb"]
        objects = tuple(
            ThorObject(
                object_id=str(o["objectId"]),
                object_type=str(o["objectType"]),
                aabb_center=_vec(o["aabb_center"]),
                aabb_size=_vec(o["aabb_size"]),
                pickupable=bool(o["pickupable"]),
                openable=bool(o["openable"]),
                parents=tuple(str(p) for p in o.get("parentReceptacles") or ()),
                name=str(o.get("name", "")),
                position=_vec(o["position"]) if "position" in o else None,
                yaw_deg=float(o["rotation"]["y"]) if "rotation" in o else 0.0,
            )
            for o in raw["objects"]
        )
        return ThorScene(
            name=str(raw["scene"]),
            room_type=str(raw["roomType"]),
            floor_center=_vec(floor["center"]),
            floor_size=_vec(floor["size"]),
            objects=objects,
            path=path,
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise SourceDataError(path, needed_for, f"unexpected scene metadata ({exc!r})") from exc


def load_layout(source: Path, floorplan: str, needed_for: str) -> npt.NDArray[np.float64]:
    """ALFRED's reachable Unity (x, z) points, shape (K, 2)."""
    path = require(layout_path(source, floorplan), needed_for)
    try:
        points = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise SourceDataError(path, needed_for, f"unreadable .npy ({exc})") from exc
    if points.ndim != 2 or points.shape[1] != 2 or len(points) == 0:
        raise SourceDataError(
            path, needed_for, f"expected a non-empty (K, 2) array, got {points.shape}"
        )
    return np.asarray(points, dtype=np.float64)


def load_openable(
    source: Path, floorplan: str, needed_for: str
) -> dict[str, tuple[float, float, float, float]]:
    """ALFRED interaction poses: objectId -> (x, z, yaw_deg, horizon_deg), Unity frame."""
    path = openable_path(source, floorplan)
    raw = _load_json(path, needed_for)
    try:
        return {
            str(k): (float(v[0]), float(v[1]), float(v[2]), float(v[3])) for k, v in raw.items()
        }
    except (AttributeError, IndexError, TypeError, ValueError) as exc:
        raise SourceDataError(path, needed_for, f"unexpected pose table ({exc!r})") from exc


def load_cooccurrence(source: Path, needed_for: str) -> CooccurrenceMatrix:
    path = require(source / VG_MATRIX, needed_for)
    try:
        with path.open(encoding="utf-8", newline="") as handle:
            rows = list(csv.reader(handle))
        names = tuple(rows[0][1:])
        if tuple(row[0] for row in rows[1:]) != names:
            raise ValueError("row names differ from column names")
        # Some cells carry a leading space (" 95"); int() accepts that.
        counts = tuple(tuple(int(cell) for cell in row[1:]) for row in rows[1:])
    except (IndexError, ValueError, UnicodeDecodeError) as exc:
        raise SourceDataError(path, needed_for, f"unexpected co-occurrence CSV ({exc})") from exc
    if any(len(row) != len(names) for row in counts):
        raise SourceDataError(path, needed_for, "co-occurrence matrix is not square")
    return CooccurrenceMatrix(names=names, counts=counts, path=path)
