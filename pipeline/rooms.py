"""One iTHOR room converted to the home map: viewpoints, door, starts, statics, objects, poses."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from . import navgrid
from .errors import SourceDataError
from .frames import Vec3
from .geometry import Box, RoomFrame
from .navgrid import GRID_M, Cell, Footprint
from .sources import ThorObject, ThorScene, layout_path, openable_path
from .vocabulary import SEMI_DYNAMIC_BY_THOR_TYPE, STATIC_BY_THOR_TYPE

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
# A semi-dynamic object whose parent is not one of our statics still "rests on" the nearest
# static if it is this close to its box (a cup in a cabinet above a counter is not on the counter).
SUPPORT_RADIUS_M = 0.5
# AI2-THOR models a sink and a bathtub twice: the whole fixture and its basin, at nearly the same
# place. Keep the basin (where objects go) and drop the fixture whose footprint contains it.
PREFERRED_PART: dict[str, str] = {"Sink": "SinkBasin", "Bathtub": "BathtubBasin"}
# Openable in AI2-THOR, but the opening is a lid, not storage: nothing placed "at" a toilet is
# inside it, and a closed toilet must not hide the toilet paper on it.
OPENABLE_NOT_CONTAINER: frozenset[str] = frozenset({"Toilet"})
# Where an ALFRED receptacle id matches one of our statics (same type, id positions this close).
ALFRED_MATCH_M = 0.5


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
class Static:
    id: str
    thor_type: str
    cls: str
    box: Box
    openable: bool
    container: bool
    # Where AI2-THOR rests pickupable objects on/in this static: (x, y, height of the surface),
    # i.e. each such object's box bottom-centre. Real surface points, unlike the box centre, which
    # for an L-shaped counter lies over the floor and for a sofa at backrest height.
    rest_points: tuple[Vec3, ...] = ()

    def to_json(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "thor_type": self.thor_type,
            "cls": self.cls,
            "center": self.box.center,
            "size": self.box.size,
            "container": self.container,
            "openable": self.openable,
            "rest_points": self.rest_points,
        }


@dataclass(frozen=True)
class PlacedObject:
    id: str
    thor_type: str
    cls: str
    box: Box
    support: str | None
    support_rule: str | None  # "parent" (parentReceptacles) or "nearest"; None without support
    inside: bool

    def to_json(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "thor_type": self.thor_type,
            "cls": self.cls,
            "center": self.box.center,
            "size": self.box.size,
            "support": self.support,
            "support_rule": self.support_rule,
            "inside": self.inside,
        }


@dataclass(frozen=True)
class AlfredPose:
    object_id: str
    thor_type: str
    center: Vec3
    pose: tuple[float, float, float]
    horizon_deg: float
    static_id: str | None
    on_viewpoint: bool

    def to_json(self) -> dict[str, Any]:
        return {
            "object_id": self.object_id,
            "thor_type": self.thor_type,
            "center": self.center,
            "pose": self.pose,
            "horizon_deg": self.horizon_deg,
            "static_id": self.static_id,
            "on_viewpoint": self.on_viewpoint,
        }


@dataclass(frozen=True)
class Start:
    name: str
    x: float
    y: float
    yaw: float

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "x": self.x, "y": self.y, "yaw": self.yaw}


@dataclass(frozen=True)
class Room:
    name: str
    room_type: str
    source_scene: str
    offset: tuple[float, float]
    extent_min: tuple[float, float]
    extent_max: tuple[float, float]
    viewpoints: tuple[Cell, ...]
    removed_inside_furniture: tuple[tuple[Cell, str], ...]  # cell (world) and the obstacle's id
    removed_disconnected: int
    walkable_components: int
    door: Cell
    starts: tuple[Start, Start]
    statics: tuple[Static, ...]
    merged_statics: tuple[tuple[str, str], ...]  # (dropped fixture id, kept basin id)
    objects: tuple[PlacedObject, ...]
    alfred_poses: tuple[AlfredPose, ...]

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


def _statics(
    scene: ThorScene, room: str, frame: RoomFrame
) -> tuple[tuple[Static, ...], dict[str, str]]:
    """Statics sorted by id, and dropped fixture thor id -> kept basin static id."""
    candidates = [o for o in scene.objects if o.object_type in STATIC_BY_THOR_TYPE]
    boxes = {o.object_id: frame.box(o.aabb_center, o.aabb_size) for o in candidates}
    merged: dict[str, str] = {}
    for whole in candidates:
        part_type = PREFERRED_PART.get(whole.object_type)
        if part_type is None:
            continue
        wbox = boxes[whole.object_id]
        parts = [
            p
            for p in candidates
            if p.object_type == part_type
            and wbox.footprint_contains(boxes[p.object_id].center[0], boxes[p.object_id].center[1])
        ]
        if parts:
            nearest = min(
                parts,
                key=lambda p: (
                    math.dist(boxes[p.object_id].center, wbox.center),
                    p.object_id,
                ),
            )
            merged[whole.object_id] = f"{room}/{nearest.object_id}"
    statics = [
        Static(
            id=f"{room}/{o.object_id}",
            thor_type=o.object_type,
            cls=STATIC_BY_THOR_TYPE[o.object_type].name,
            box=boxes[o.object_id],
            openable=o.openable,
            container=o.openable and o.object_type not in OPENABLE_NOT_CONTAINER,
        )
        for o in candidates
        if o.object_id not in merged
    ]
    ids = {s.id for s in statics}
    rest: dict[str, list[Vec3]] = {s.id: [] for s in statics}
    for obj in scene.objects:
        sid = _parent_static(obj, room, ids, merged) if obj.pickupable else None
        if sid is not None:
            box = frame.box(obj.aabb_center, obj.aabb_size)
            rest[sid].append((box.center[0], box.center[1], box.lo[2]))
    placed = (replace(s, rest_points=tuple(sorted(rest[s.id]))) for s in statics)
    return tuple(sorted(placed, key=lambda s: s.id)), merged


def _parent_static(obj: ThorObject, room: str, ids: set[str], merged: dict[str, str]) -> str | None:
    """The first of the object's parentReceptacles that is one of our statics (after merging)."""
    for parent in obj.parents:
        sid = merged.get(parent, f"{room}/{parent}")
        if sid in ids:
            return sid
    return None


def _support(
    obj: ThorObject,
    center: Vec3,
    room: str,
    statics: tuple[Static, ...],
    merged: dict[str, str],
) -> tuple[Static | None, str | None]:
    by_id = {s.id: s for s in statics}
    sid = _parent_static(obj, room, set(by_id), merged)
    if sid is not None:
        return by_id[sid], "parent"
    near = [(s.box.distance_to(center), s.id, s) for s in statics]
    near = [n for n in near if n[0] <= SUPPORT_RADIUS_M]
    if not near:
        return None, None
    return min(near, key=lambda n: (n[0], n[1]))[2], "nearest"


def _objects(
    scene: ThorScene,
    room: str,
    frame: RoomFrame,
    statics: tuple[Static, ...],
    merged: dict[str, str],
) -> tuple[PlacedObject, ...]:
    placed = []
    for obj in scene.objects:
        cls = SEMI_DYNAMIC_BY_THOR_TYPE.get(obj.object_type)
        if cls is None:
            continue
        box = frame.box(obj.aabb_center, obj.aabb_size)
        support, rule = _support(obj, box.center, room, statics, merged)
        placed.append(
            PlacedObject(
                id=f"{room}/{obj.object_id}",
                thor_type=obj.object_type,
                cls=cls.name,
                box=box,
                support=support.id if support else None,
                support_rule=rule,
                inside=bool(support and support.container),
            )
        )
    return tuple(sorted(placed, key=lambda o: o.id))


def _id_position(object_id: str) -> Vec3 | None:
    """The Unity position an AI2-THOR id carries: ``Type|x|y|z`` (``|Part`` may follow)."""
    parts = object_id.split("|")
    if len(parts) not in (4, 5):
        return None
    try:
        return (float(parts[1]), float(parts[2]), float(parts[3]))
    except ValueError:
        return None


def _id_type(object_id: str) -> str:
    """``Sink|...|SinkBasin`` names the basin, a part of the sink: the last field is its type."""
    parts = object_id.split("|")
    return parts[4] if len(parts) == 5 else parts[0]


def _alfred_poses(
    src: RoomSource,
    room: str,
    frame: RoomFrame,
    statics: tuple[Static, ...],
    viewpoints: frozenset[Cell],
) -> tuple[AlfredPose, ...]:
    path = openable_path(src.source, src.scene.name)
    static_positions = [(s, _id_position(s.id.split("/", 1)[1])) for s in statics]
    poses = []
    for object_id, (x, z, yaw_deg, horizon) in sorted(src.openable.items()):
        unity_pos = _id_position(object_id)
        if unity_pos is None:
            raise SourceDataError(
                path,
                f"ALFRED poses of {src.scene.name}",
                f"object id {object_id!r} has no position",
            )
        thor_type = _id_type(object_id)
        matches = [
            (math.dist(unity_pos, pos), s.id)
            for s, pos in static_positions
            if pos is not None and s.thor_type == thor_type
        ]
        matches = [m for m in matches if m[0] <= ALFRED_MATCH_M]
        px, py = frame.floor_point(x, z)
        poses.append(
            AlfredPose(
                object_id=f"{room}/{object_id}",
                thor_type=thor_type,
                center=frame.point(unity_pos),
                pose=(px, py, frame.yaw(yaw_deg)),
                horizon_deg=horizon,
                static_id=min(matches)[1] if matches else None,
                on_viewpoint=navgrid.to_cell(px, py) in viewpoints,
            )
        )
    return tuple(poses)


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


def build_room(src: RoomSource, slot: RoomSlot, min_x: float) -> Room:
    """Convert one room and place it so that its extent starts at ``min_x`` (rounded up) and y=0."""
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

    local_statics, _ = _statics(scene, slot.name, local)
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
    statics, merged = _statics(scene, slot.name, frame)
    first, second, _ = navgrid.farthest_pair(viewpoints)
    cx = sum(c[0] for c in viewpoints) * GRID_M / len(viewpoints)
    cy = sum(c[1] for c in viewpoints) * GRID_M / len(viewpoints)
    starts = tuple(
        Start(f"{slot.name}-{k}", x, y, math.atan2(cy - y, cx - x))
        for k, (x, y) in enumerate((navgrid.cell_xy(first), navgrid.cell_xy(second)), start=1)
    )
    return Room(
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
        removed_disconnected=sum(len(p) for p in pieces[1:]),
        walkable_components=navgrid.walkable_components(viewpoints),
        door=navgrid.door(viewpoints),
        starts=(starts[0], starts[1]),
        statics=statics,
        merged_statics=tuple(sorted((f"{slot.name}/{k}", v) for k, v in merged.items())),
        objects=_objects(scene, slot.name, frame, statics, merged),
        alfred_poses=_alfred_poses(src, slot.name, frame, statics, viewpoints),
    )
