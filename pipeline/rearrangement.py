"""``data/rearrangement/<home>.json``: where real AI2-THOR rearrangement episodes put our targets.

The AI2-THOR Rearrangement 2022 dataset (``ai2thor/rearrangement``) gives, per iTHOR FloorPlan, 50
episodes, each with the ``target_poses`` (the room as it should be) and ``starting_poses`` (the
room after a few objects were moved) of every movable object: name, pivot position and rotation,
Unity frame. For each room of an iTHOR-based home we keep the poses of our semi-dynamic classes:

- a pose is tied to the object of the scene metadata with the same name; the object's box centre is
  its pivot plus the metadata's pivot -> box-centre offset turned by the change of yaw, and the box
  goes through the same ``RoomFrame`` (Unity -> REP-103, then the room's offset) as the home;
- the object is attributed to the static it rests on or in (:func:`attribute`): the statics whose
  box lies within ``SUPPORT_TOLERANCE_M`` of the object's bottom centre, and among those the one
  whose top is nearest that height (a cup *on* a counter, not the shelf beneath it), then the one
  whose centre is nearest (the basin, not the counter around it). Without any, the nearest static
  box within ``SUPPORT_RADIUS_M`` (the rule of the home's own objects). A pose farther than that
  from every static (in a cabinet, on a dresser, on the floor) is dropped and counted.

Poses carry no parentReceptacles, so the home's first rule (parent, then nearest) cannot be used;
on the metadata's own poses this rule names the parent's class for 97% of the objects (a test).
"""

from __future__ import annotations

import gzip
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from objsearch.agent.geometry import Vec3

from .errors import SourceDataError
from .geometry import RoomFrame
from .home import SourceHome
from .room_objects import SUPPORT_RADIUS_M, Static
from .rooms import ConvertedRoom
from .sources import ThorObject, ThorScene
from .vocabulary import SEMI_DYNAMIC_BY_THOR_TYPE

REARRANGEMENT = Path("ai2thor/rearrangement")
SPLITS: tuple[str, ...] = ("2022_train", "2022_val")
#: A static box this close to an object's bottom centre holds it (rests on it or contains it).
SUPPORT_TOLERANCE_M = 0.02
#: Starting poses within this of the target pose, on the same static, are the same placement: the
#: source's physics moves untouched objects by millimetres between the two.
SETTLE_M = 0.01
PHASES: tuple[tuple[str, str], ...] = (("target", "target_poses"), ("start", "starting_poses"))
FORMAT = "objsearch.rearrangement/1"


@dataclass(frozen=True)
class Episodes:
    """FloorPlan -> (split, its episodes as in the source)."""

    by_scene: Mapping[str, tuple[str, tuple[Mapping[str, Any], ...]]]
    files: tuple[Path, ...]  # relative to the source root


def load_episodes(source: Path) -> Episodes:
    what = "the rearrangement placements (data/rearrangement/)"
    by_scene: dict[str, tuple[str, tuple[Mapping[str, Any], ...]]] = {}
    files = []
    for split in SPLITS:
        rel = REARRANGEMENT / f"{split}.json.gz"
        path = source / rel
        if not path.is_file():
            raise SourceDataError(path, what)
        try:
            with gzip.open(path, "rt", encoding="utf-8") as handle:
                doc = json.load(handle)
            for scene, episodes in doc.items():
                by_scene[str(scene)] = (split, tuple(episodes))
        except (OSError, EOFError, ValueError, AttributeError) as exc:
            raise SourceDataError(path, what, f"unreadable gzip JSON ({exc})") from None
        files.append(rel)
    return Episodes(by_scene=by_scene, files=tuple(files))


def attribute(rest: Vec3, statics: Sequence[Static]) -> tuple[Static, float] | None:
    """The static holding an object whose bottom centre is ``rest``, and the distance to its box."""

    def key(s: Static) -> tuple[bool, float, float, float, str]:
        d = s.box.distance_to(rest)
        holds = d <= SUPPORT_TOLERANCE_M
        top_gap = round(abs(rest[2] - s.box.hi[2]), 2)  # cm: closer tops tie, then the centre
        centre = math.hypot(rest[0] - s.box.center[0], rest[1] - s.box.center[1])
        return (not holds, 0.0 if holds else d, top_gap if holds else 0.0, centre, s.id)

    if not statics:
        return None
    best = min(statics, key=key)
    d = best.box.distance_to(rest)
    return (best, d) if d <= SUPPORT_RADIUS_M else None


def pose_center(obj: ThorObject, pose: Mapping[str, Any]) -> Vec3:
    """Unity box centre of ``obj`` at an episode pose (pivot + offset turned by the yaw change)."""
    if obj.position is None:
        raise ValueError(f"{obj.object_id} has no pivot position in the scene metadata")
    pos, rot = pose["position"], pose["rotation"]
    off = [c - p for c, p in zip(obj.aabb_center, obj.position, strict=True)]
    turn = math.radians(float(rot["y"]) - obj.yaw_deg)
    # Unity yaw turns clockwise seen from above (left-handed, y up).
    ox = off[0] * math.cos(turn) + off[2] * math.sin(turn)
    oz = -off[0] * math.sin(turn) + off[2] * math.cos(turn)
    return (float(pos["x"]) + ox, float(pos["y"]) + off[1], float(pos["z"]) + oz)


def _moved(a: Sequence[Any] | None, b: Sequence[Any] | None) -> bool:
    """Whether the starting pose differs from the target pose (beyond physics settling)."""
    if a is None or b is None:
        return a is not b
    return a[3] != b[3] or math.dist(a[:3], b[:3]) > SETTLE_M


@dataclass(frozen=True)
class RoomCounts:
    kept: int
    dropped: int  # near no static
    absent: int  # not in the episode at all


def _room_json(
    room: ConvertedRoom, scene: ThorScene, split: str, episodes: Sequence[Mapping[str, Any]]
) -> tuple[dict[str, Any], RoomCounts]:
    frame = RoomFrame(*room.offset)
    by_name = {
        o.name: o
        for o in scene.objects
        if o.object_type in SEMI_DYNAMIC_BY_THOR_TYPE and o.name and o.position is not None
    }
    names = sorted(
        {p["name"] for e in episodes for _, k in PHASES for p in e[k] if p["name"] in by_name}
    )
    objects = [by_name[n] for n in names]
    statics: list[str] = []
    kept = dropped = absent = 0
    rows_out = []
    for index, episode in enumerate(episodes):
        phase_rows: dict[str, list[list[Any] | None]] = {}
        for phase, key in PHASES:
            poses = {p["name"]: p for p in episode[key]}
            rows: list[list[Any] | None] = []
            for obj in objects:
                pose = poses.get(obj.name)
                if pose is None:  # some episodes leave an object out altogether
                    rows.append(None)
                    absent += 1
                    continue
                box = frame.box(pose_center(obj, pose), obj.aabb_size)
                held = attribute((box.center[0], box.center[1], box.lo[2]), room.statics)
                if held is None:
                    rows.append(None)
                    dropped += 1
                    continue
                static, d = held
                if static.id not in statics:
                    statics.append(static.id)
                rows.append([*box.center, statics.index(static.id), d])
                kept += 1
            phase_rows[phase] = rows
        target, start = phase_rows["target"], phase_rows["start"]
        moved = {
            str(i): b for i, (a, b) in enumerate(zip(target, start, strict=True)) if _moved(a, b)
        }
        rows_out.append({"index": index, "target": target, "moved": moved})
    doc = {
        "name": room.name,
        "source_scene": scene.name,
        "split": split,
        "objects": [
            {
                "id": f"{room.name}/{o.object_id}",
                "name": o.name,
                "cls": SEMI_DYNAMIC_BY_THOR_TYPE[o.object_type].name,
                "size": frame.box(o.aabb_center, o.aabb_size).size,
            }
            for o in objects
        ],
        "statics": statics,
        "kept": kept,
        "dropped": dropped,
        "absent": absent,
        "episodes": rows_out,
    }
    return doc, RoomCounts(kept, dropped, absent)


def rearrangement_json(
    home: SourceHome, scenes: Mapping[str, ThorScene], episodes: Episodes, source: Path
) -> tuple[dict[str, Any], RoomCounts]:
    """The derived file for one iTHOR home; ``scenes`` maps FloorPlan -> its metadata."""
    rooms = []
    kept = dropped = absent = 0
    for room in home.rooms:
        found = episodes.by_scene.get(room.source_scene)
        if found is None:
            raise SourceDataError(
                source / REARRANGEMENT,
                f"the rearrangement placements of home {home.name!r}",
                f"no episodes for {room.source_scene}",
            )
        split, eps = found
        doc, counts = _room_json(room, scenes[room.source_scene], split, eps)
        rooms.append(doc)
        kept += counts.kept
        dropped += counts.dropped
        absent += counts.absent
    return {
        "format": FORMAT,
        "home": home.name,
        "source": [f.as_posix() for f in episodes.files],
        "notes": (
            "Per room, per source episode (index), per object of 'objects': 'target' rows are "
            "[x, y, z, s, d] at the episode's target pose: the box centre (REP-103, home frame), "
            "the index s of the static in 'statics' it rests on or in, and the distance d (m) from "
            f"the object's bottom centre to that static's box; null where no static box is within "
            f"{SUPPORT_RADIUS_M} m (dropped) or the episode does not have the object (absent). "
            "'moved' gives the starting-pose row of each object (by index) whose starting pose "
            f"differs (another static, or more than {SETTLE_M} m away); the others start where "
            "they should end. "
            "See pipeline/rearrangement.py."
        ),
        "support_radius": SUPPORT_RADIUS_M,
        "support_tolerance": SUPPORT_TOLERANCE_M,
        "kept": kept,
        "dropped": dropped,
        "absent": absent,
        "rooms": rooms,
    }, RoomCounts(kept, dropped, absent)
