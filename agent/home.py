"""A home as the agent and the simulator know it: rooms, viewpoints, static objects, placements.

Loaded from ``data/homes/<name>.json`` (see docs/data-format.md); all coordinates are REP-103.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from objsearch.agent.categories import read_json
from objsearch.agent.datapaths import data_dir
from objsearch.agent.errors import DataFileError, UnknownStartError
from objsearch.agent.geometry import Point, Pose, Vec3


@dataclass(frozen=True, slots=True)
class Box:
    """An axis-aligned bounding box: ``center`` and full ``size`` per axis, map (ROS) frame.
    The one box type: the converter builds homes from it and the agent reads them back."""

    center: Vec3
    size: Vec3

    @property
    def lo(self) -> Vec3:
        c, s = self.center, self.size
        return (c[0] - s[0] / 2, c[1] - s[1] / 2, c[2] - s[2] / 2)

    @property
    def hi(self) -> Vec3:
        c, s = self.center, self.size
        return (c[0] + s[0] / 2, c[1] + s[1] / 2, c[2] + s[2] / 2)

    def distance_to(self, p: Vec3) -> float:
        """Euclidean distance from a point to the box (0 inside)."""
        acc = 0.0
        for c, s, v in zip(self.center, self.size, p, strict=True):
            excess = abs(v - c) - s / 2
            if excess > 0:
                acc += excess * excess
        return float(acc**0.5)

    def footprint_contains(self, x: float, y: float) -> bool:
        """Whether (x, y) lies in the box's footprint, edges included."""
        lo, hi = self.lo, self.hi
        return lo[0] <= x <= hi[0] and lo[1] <= y <= hi[1]

    def contains_xy(self, pt: Point) -> bool:
        """Whether ``pt`` lies strictly inside the box's footprint."""
        return (
            abs(pt.x - self.center[0]) < self.size[0] / 2
            and abs(pt.y - self.center[1]) < self.size[1] / 2
        )

    @property
    def top(self) -> float:
        return self.center[2] + self.size[2] / 2


@dataclass(frozen=True, slots=True)
class StaticObject:
    id: str
    thor_type: str
    cls: str
    box: Box
    container: bool
    room: str


@dataclass(frozen=True, slots=True)
class MovableObject:
    """A semi-dynamic object instance as it appears in the source scene."""

    id: str
    thor_type: str
    cls: str
    box: Box
    support: str | None
    inside: bool
    room: str


@dataclass(frozen=True, slots=True)
class Room:
    name: str
    room_type: str
    source_scene: str
    viewpoints: tuple[Point, ...]
    door: Point
    starts: tuple[tuple[str, Pose], ...]
    statics: tuple[StaticObject, ...]
    objects: tuple[MovableObject, ...]
    alfred_poses: tuple[Mapping[str, Any], ...]


@dataclass(frozen=True)
class Home:
    name: str
    grid: float
    rooms: tuple[Room, ...]
    digest: str
    #: Walkable steps between viewpoints of two rooms (doors, open walls) in a house whose rooms
    #: share one floor plan; empty for iTHOR homes, whose rooms are joined by the teleport.
    links: tuple[tuple[Point, Point], ...] = ()
    #: Rooms joined the paper's way (zero-cost teleport between entry viewpoints) or walked.
    teleport: bool = True

    def room(self, name: str) -> Room:
        for room in self.rooms:
            if room.name == name:
                return room
        raise KeyError(f"no room {name!r} in home {self.name!r}")

    @property
    def statics(self) -> dict[str, StaticObject]:
        return {s.id: s for room in self.rooms for s in room.statics}

    @property
    def objects(self) -> dict[str, MovableObject]:
        return {o.id: o for room in self.rooms for o in room.objects}

    @property
    def starts(self) -> dict[str, Pose]:
        return {name: pose for room in self.rooms for name, pose in room.starts}

    def start(self, name: str) -> Pose:
        starts = self.starts
        if name not in starts:
            raise UnknownStartError(
                f"unknown start point {name!r} in home {self.name!r}; choose one of: "
                f"{', '.join(starts)}"
            )
        return starts[name]

    def room_of_start(self, name: str) -> str:
        for room in self.rooms:
            if any(start == name for start, _ in room.starts):
                return room.name
        raise UnknownStartError(f"unknown start point {name!r}")


def _vec3(v: Any) -> Vec3:
    return (float(v[0]), float(v[1]), float(v[2]))


def _room(doc: Mapping[str, Any]) -> Room:
    name = doc["name"]
    return Room(
        name=name,
        room_type=doc["room_type"],
        source_scene=doc["source_scene"],
        viewpoints=tuple(Point(float(x), float(y)) for x, y in doc["viewpoints"]),
        door=Point(float(doc["door"][0]), float(doc["door"][1])),
        starts=tuple(
            (s["name"], Pose(float(s["x"]), float(s["y"]), float(s["yaw"]))) for s in doc["starts"]
        ),
        statics=tuple(
            StaticObject(
                id=s["id"],
                thor_type=s["thor_type"],
                cls=s["cls"],
                box=Box(_vec3(s["center"]), _vec3(s["size"])),
                container=bool(s["container"]),
                room=name,
            )
            for s in doc["statics"]
        ),
        objects=tuple(
            MovableObject(
                id=o["id"],
                thor_type=o["thor_type"],
                cls=o["cls"],
                box=Box(_vec3(o["center"]), _vec3(o["size"])),
                support=o.get("support"),
                inside=bool(o.get("inside", False)),
                room=name,
            )
            for o in doc["objects"]
        ),
        alfred_poses=tuple(doc.get("alfred_poses", ())),
    )


def home_path(name: str, data: Path | None = None) -> Path:
    """The file of home ``name`` in the data folder ``data`` (None: ``datapaths.data_dir()``)."""
    return data_dir(data) / "homes" / f"{name}.json"


def available_homes(data: Path | None = None) -> tuple[str, ...]:
    folder = data_dir(data) / "homes"
    return tuple(sorted(p.stem for p in folder.glob("*.json"))) if folder.is_dir() else ()


def load_home(name_or_path: str | Path, data: Path | None = None) -> Home:
    """Load a home by name (``homes/<name>.json`` of the data folder ``data``; None:
    ``datapaths.data_dir()``) or by path."""
    path = Path(name_or_path)
    if path.suffix != ".json":
        path = home_path(str(name_or_path), data)
        if not path.exists():
            raise DataFileError(
                f"no home {str(name_or_path)!r} in {path.parent} (available: "
                f"{', '.join(available_homes(data)) or 'none'}); run `objsearch data build`"
            )
    doc = read_json(path, "a home")
    try:
        rooms = tuple(_room(r) for r in doc["rooms"])
        return Home(
            name=doc["name"],
            grid=float(doc["grid"]),
            rooms=rooms,
            digest=hashlib.sha256(path.read_bytes()).hexdigest()[:16],
            links=tuple(
                (Point(float(a[0]), float(a[1])), Point(float(b[0]), float(b[1])))
                for a, b in doc.get("links", ())
            ),
            teleport=bool(doc.get("teleport", True)),
        )
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise DataFileError(f"home file {path} is malformed: {exc!r}") from None
