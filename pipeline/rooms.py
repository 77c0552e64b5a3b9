"""One iTHOR room converted to the home map: viewpoints, door, starts, and what it contains."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from . import navgrid
from .alfred_poses import AlfredPose, alfred_poses
from .errors import SourceDataError
from .geometry import RoomFrame
from .navgrid import GRID_M, Cell, Footprint
from .room_objects import PlacedObject, Static, objects_of, statics_of
from .sources import ThorObject, ThorScene, layout_path, openable_path

# Things that are not obstacles although they sit low or report the floor as their parent: the
# floor itself, and objects fixed to walls or hanging (their aabb reaches down but the robot
# passes under or beside them). Checked against every type present in the 100 iTHOR scenes;
# none of these removes an ALFRED grid point today, the list guards the rule.
NOT_OBSTACLES: frozenset[str] = frozenset(
    {
        "Floor",
        "Window",
        "Curtains",
        "Blinds",
        "Painting",
        "Poster",
        "Mirror",
        "LightSwitch",
        "ShowerCurtain",
        "ShowerHead",
        "Faucet",
        "Towel",
        "HandTowel",
        "TowelHolder",
        "HandTowelHolder",
        "ToiletPaperHanger",
    }
)
# An object whose box starts less than this above the floor stands on the floor (a cabinet, a
# sofa); one that starts higher is on something else (a microwave on a counter).
FLOOR_CONTACT_M = 0.3


@dataclass(frozen=True)
class RoomSlot:
    name: str
    room_type: str


ROOM_SLOTS: tuple[RoomSlot, ...] = (
    RoomSlot("kitchen", "Kitchen"),
    RoomSlot("living", "LivingRoom"),
    RoomSlot("bedroom", "Bedroom"),
    RoomSlot("bathroom", "Bathroom"),
)


@dataclass(frozen=True)
class Start:
    name: str
    x: float
    y: float
    yaw: float

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "x": self.x, "y": self.y, "yaw": self.yaw}


@dataclass(frozen=True)
class ConvertedRoom:
    name: str
    room_type: str
    source_scene: str
    offset: tuple[float, float]
    extent_min: tuple[float, float]
    extent_max: tuple[float, float]
    viewpoints: tuple[Cell, ...]
    removed_inside_furniture: tuple[tuple[Cell, str], ...]  # cell (world) and the obstacle's id
    removed_disconnected: int
    # Sizes of the pieces the viewpoints fall into when diagonal steps must not cut corners,
    # largest first; more than one means part of the room cannot be walked to.
    walkable_piece_sizes: tuple[int, ...]
    door: Cell
    starts: tuple[Start, Start]
    statics: tuple[Static, ...]
    merged_statics: tuple[tuple[str, str], ...]  # (dropped fixture id, kept basin id)
    objects: tuple[PlacedObject, ...]
    alfred_poses: tuple[AlfredPose, ...]

    @property
    def walkable_components(self) -> int:
        return len(self.walkable_piece_sizes)

    @property
    def removed_viewpoints(self) -> int:
        return len(self.removed_inside_furniture) + self.removed_disconnected

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "room_type": self.room_type,
            "source_scene": self.source_scene,
            "offset": self.offset,
            "extent": {"min": self.extent_min, "max": self.extent_max},
            "viewpoints": [navgrid.cell_xy(c) for c in self.viewpoints],
            "removed_viewpoints": self.removed_viewpoints,
            "removed_inside_furniture": [
                {"xy": navgrid.cell_xy(c), "obstacle": label}
                for c, label in self.removed_inside_furniture
            ],
            "removed_disconnected": self.removed_disconnected,
            "walkable_components": self.walkable_components,
            "door": navgrid.cell_xy(self.door),
            "starts": [s.to_json() for s in self.starts],
            "statics": [s.to_json() for s in self.statics],
            "merged_statics": dict(self.merged_statics),
            "objects": [o.to_json() for o in self.objects],
            "alfred_poses": [p.to_json() for p in self.alfred_poses],
        }


@dataclass(frozen=True)
class RoomSource:
    """The raw inputs of one room."""

    scene: ThorScene
    layout: npt.NDArray[np.float64]
    openable: dict[str, tuple[float, float, float, float]]
    source: Path


def _floor_top(scene: ThorScene) -> float:
    return scene.floor_center[1] + scene.floor_size[1] / 2


def _stands_on_floor(obj: ThorObject, floor_top: float) -> bool:
    bottom = obj.aabb_center[1] - obj.aabb_size[1] / 2
    return bottom - floor_top < FLOOR_CONTACT_M or any(p.startswith("Floor|") for p in obj.parents)


def obstacle_footprints(scene: ThorScene, frame: RoomFrame) -> list[Footprint]:
    top = _floor_top(scene)
    prints = []
    for obj in scene.objects:
        if obj.pickupable or obj.object_type in NOT_OBSTACLES or not _stands_on_floor(obj, top):
            continue
        box = frame.box(obj.aabb_center, obj.aabb_size)
        lo, hi = box.lo, box.hi
        prints.append(Footprint(obj.object_id, lo[0], hi[0], lo[1], hi[1]))
    return prints


def _grid_cells(src: RoomSource) -> set[Cell]:
    cells = set()
    for ux, uz in src.layout.tolist():
        x, y = RoomFrame().floor_point(ux, uz)
        cell = navgrid.to_cell(x, y)
        if cell is None:
            raise SourceDataError(
                layout_path(src.source, src.scene.name),
                f"the navigation grid of {src.scene.name}",
                f"point ({ux}, {uz}) is not on the {GRID_M} m lattice",
            )
        cells.add(cell)
    return cells


def _snap_up(value: float) -> float:
    """Round up to the lattice so that shifted grid points stay on it and gaps never shrink."""
    return math.ceil(value / GRID_M - 1e-9) * GRID_M + 0.0


def build_room(
    src: RoomSource, slot: RoomSlot, min_x: float, *, largest_walkable_piece: bool = False
) -> ConvertedRoom:
    """Convert one room and place it so that its extent starts at ``min_x`` (rounded up) and y=0.

    ``largest_walkable_piece``: keep only the largest piece of the walking graph (diagonal steps
    may not cut corners), for a room in pieces the user accepted (``--accept split-rooms``); the
    other pieces' points count as disconnected."""
    scene = src.scene
    local = RoomFrame()
    cells = _grid_cells(src)
    free, inside = navgrid.split_by_footprints(cells, obstacle_footprints(scene, local))
    pieces = navgrid.components_8(free)
    if not pieces:
        raise SourceDataError(
            layout_path(src.source, scene.name),
            f"the navigation grid of {scene.name}",
            "every grid point lies inside furniture",
        )
    main = pieces[0]
    cut = 0
    if largest_walkable_piece:
        walkable = navgrid.walkable_pieces(main)
        main, cut = walkable[0], sum(len(p) for p in walkable[1:])

    local_statics, _ = statics_of(scene, slot.name, local)
    floor = local.box(scene.floor_center, scene.floor_size)
    xs = [floor.lo[0], floor.hi[0]] + [c[0] * GRID_M for c in main]
    ys = [floor.lo[1], floor.hi[1]] + [c[1] * GRID_M for c in main]
    for s in local_statics:
        xs += [s.box.lo[0], s.box.hi[0]]
        ys += [s.box.lo[1], s.box.hi[1]]
    dx, dy = _snap_up(min_x - min(xs)), _snap_up(-min(ys))
    di, dj = round(dx / GRID_M), round(dy / GRID_M)

    frame = RoomFrame(dx, dy)
    viewpoints = frozenset((i + di, j + dj) for i, j in main)
    statics, merged = statics_of(scene, slot.name, frame)
    first, second, _ = navgrid.farthest_pair(viewpoints)
    cx = sum(c[0] for c in viewpoints) * GRID_M / len(viewpoints)
    cy = sum(c[1] for c in viewpoints) * GRID_M / len(viewpoints)
    starts = tuple(
        Start(f"{slot.name}-{k}", x, y, math.atan2(cy - y, cx - x))
        for k, (x, y) in enumerate((navgrid.cell_xy(first), navgrid.cell_xy(second)), start=1)
    )
    return ConvertedRoom(
        name=slot.name,
        room_type=slot.room_type,
        source_scene=scene.name,
        offset=(dx, dy),
        extent_min=(min(xs) + dx, min(ys) + dy),
        extent_max=(max(xs) + dx, max(ys) + dy),
        viewpoints=tuple(sorted(viewpoints)),
        removed_inside_furniture=tuple(
            sorted(((i + di, j + dj), f"{slot.name}/{label}") for (i, j), label in inside.items())
        ),
        removed_disconnected=sum(len(p) for p in pieces[1:]) + cut,
        walkable_piece_sizes=tuple(len(p) for p in navgrid.walkable_pieces(viewpoints)),
        door=navgrid.door(viewpoints),
        starts=(starts[0], starts[1]),
        statics=statics,
        merged_statics=tuple(sorted((f"{slot.name}/{k}", v) for k, v in merged.items())),
        objects=objects_of(scene, slot.name, frame, statics, merged),
        alfred_poses=alfred_poses(
            src.openable,
            openable_path(src.source, scene.name),
            slot.name,
            frame,
            statics,
            viewpoints,
        ),
    )
