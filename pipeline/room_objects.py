"""Statics and semi-dynamic objects of one room: instances, boxes, what rests on what."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

from objsearch.agent.geometry import Vec3
from objsearch.agent.home import Box

from .geometry import RoomFrame
from .sources import ThorObject, ThorScene
from .vocabulary import SEMI_DYNAMIC_BY_THOR_TYPE, STATIC_BY_THOR_TYPE

# A semi-dynamic object whose parent is not one of our statics still "rests on" the nearest
# static if it is this close to its box (a cup in a cabinet above a counter is not on the counter).
SUPPORT_RADIUS_M = 0.5
# AI2-THOR models a sink and a bathtub twice: the whole fixture and its basin, at nearly the same
# place. Keep the basin (where objects go) and drop the fixture whose footprint contains it.
PREFERRED_PART: dict[str, str] = {"Sink": "SinkBasin", "Bathtub": "BathtubBasin"}
# Openable in AI2-THOR, but the opening is a lid, not storage: nothing placed "at" a toilet is
# inside it, and a closed toilet must not hide the toilet paper on it.
OPENABLE_NOT_CONTAINER: frozenset[str] = frozenset({"Toilet"})


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
    # for an L-shaped counter can lie over open floor, and the box top, a sofa's backrest.
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


def statics_of(
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


def objects_of(
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
