"""A home: four iTHOR rooms (kitchen, living room, bedroom, bathroom) side by side on one map."""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import HomeSpecError
from .navgrid import GRID_M
from .room_objects import PlacedObject, Static
from .rooms import ROOM_SLOTS, ConvertedRoom, RoomSource, build_room
from .sources import load_layout, load_openable, load_scene, scene_path

ROOM_GAP_M = 1.0
_HOME_NAME = re.compile(r"[a-z0-9][a-z0-9_-]*")
_FLOORPLAN = re.compile(r"(?:FloorPlan)?([1-9][0-9]*)")

NOTES = (
    "Unity -> ROS REP-103 (x=z_u, y=-x_u, z=y_u, yaw=-yaw_u). Rooms laid along +x in the order "
    "kitchen, living, bedroom, bathroom, each shifted (offsets rounded up to the 0.25 m grid) so "
    "that its extent (floor box, viewpoints, static boxes) starts >= 1 m after the previous room "
    "and at y >= 0. Viewpoints: ALFRED grid minus points strictly inside the floor footprint of a "
    "floor-standing non-pickupable object, then the largest 8-connected component. Door: the "
    "boundary viewpoint nearest the per-axis median of boundary viewpoints. Starts: the two "
    "viewpoints farthest apart by walking distance, facing the viewpoint centroid. Sink/Bathtub "
    "fixtures containing a basin are merged into the basin. Toilet is openable (lid) but not a "
    "container. See docs/data-format.md."
)


@dataclass(frozen=True)
class SourceHome:
    """A home as the converter assembles it from AI2-THOR scenes, before it is written to
    ``data/homes/`` (the agent's :class:`objsearch.agent.home.Home` reads it from there)."""

    name: str
    rooms: tuple[ConvertedRoom, ...]

    @property
    def statics(self) -> tuple[Static, ...]:
        return tuple(s for r in self.rooms for s in r.statics)

    @property
    def objects(self) -> tuple[PlacedObject, ...]:
        return tuple(o for r in self.rooms for o in r.objects)

    def static(self, static_id: str) -> Static:
        for s in self.statics:
            if s.id == static_id:
                return s
        raise KeyError(static_id)

    def to_json(self) -> dict[str, Any]:
        return {
            "format": "objsearch.home/1",
            "name": self.name,
            "grid": GRID_M,
            "notes": NOTES,
            "rooms": [r.to_json() for r in self.rooms],
        }


def normalise_floorplan(text: str) -> str:
    """``"FloorPlan2"`` or ``"2"`` -> ``"FloorPlan2"``."""
    match = _FLOORPLAN.fullmatch(text.strip())
    if not match:
        raise HomeSpecError(f"{text!r} is not an iTHOR scene name like 'FloorPlan201'")
    return f"FloorPlan{match.group(1)}"


def check_home_name(name: str) -> str:
    if not _HOME_NAME.fullmatch(name):
        raise HomeSpecError(
            f"home name {name!r} must be lower-case letters, digits, '-' or '_' (it names a file)"
        )
    return name


def check_home_spec(name: str, floorplans: Sequence[str]) -> tuple[str, ...]:
    check_home_name(name)
    if isinstance(floorplans, str) or len(floorplans) != len(ROOM_SLOTS):
        order = ", ".join(s.name for s in ROOM_SLOTS)
        raise HomeSpecError(f"home {name!r} needs exactly {len(ROOM_SLOTS)} scenes ({order})")
    return tuple(normalise_floorplan(f) for f in floorplans)


def build_home(
    source: Path,
    name: str,
    floorplans: Sequence[str],
    progress: Callable[[str], None] | None = None,
    *,
    largest_walkable_piece: bool = False,
) -> SourceHome:
    """``largest_walkable_piece``: see :func:`build_room` (only for split rooms a user accepted)."""
    scenes = check_home_spec(name, floorplans)
    rooms: list[ConvertedRoom] = []
    min_x = 0.0
    for slot, floorplan in zip(ROOM_SLOTS, scenes, strict=True):
        if progress:
            progress(f"home {name}: {slot.name} from {floorplan}")
        purpose = f"the {slot.name} of home {name!r}"
        scene = load_scene(source, floorplan, purpose)
        if scene.room_type != slot.room_type:
            raise HomeSpecError(
                f"home {name!r}: the {slot.name} must be a {slot.room_type} scene, but {floorplan} "
                f"is a {scene.room_type} (roomType in {scene_path(source, floorplan)}); give the "
                "scenes in the order kitchen, living room, bedroom, bathroom"
            )
        src = RoomSource(
            scene=scene,
            layout=load_layout(source, floorplan, f"the navigation grid of {purpose}"),
            openable=load_openable(source, floorplan, f"the ALFRED interaction poses of {purpose}"),
            source=source,
        )
        room = build_room(src, slot, min_x, largest_walkable_piece=largest_walkable_piece)
        rooms.append(room)
        min_x = room.extent_max[0] + ROOM_GAP_M
    return SourceHome(name=name, rooms=tuple(rooms))
