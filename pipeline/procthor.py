"""Homes from ProcTHOR house files: one floor plan, rooms joined by doors and open walls.

Unlike the iTHOR homes (separate scenes laid side by side and joined by the paper's teleport), a
ProcTHOR house is one building, so the home is walked as it is:

- **Viewpoints**: the 0.25 m lattice points (ROS frame) inside a room's floor polygon at least
  ``WALL_CLEARANCE_M`` from its walls and at least ``FURNITURE_CLEARANCE_M`` outside the footprint of
  every floor-standing object (the asset's bounding box, rotated by the object's yaw), then the
  largest connected piece of the whole house.
- **Links**: a doorway (a door between two different rooms) or an open wall (``empty: true``) joins a
  viewpoint on one side to its nearest viewpoint on the other side when the straight step between
  them crosses the wall inside the opening (shrunk by ``OPENING_MARGIN_M`` at each end) and is at
  most ``MAX_LINK_M`` long. The robot walks these steps; nothing is teleported.
- **Entry** ("door") of a room: the room-side end of its links nearest their median.
- **Statics / objects**: every object (top level or child) whose AI2-THOR type is one of our
  classes, typed and sized from ``asset-database.json`` by ``assetId``. A child of a static is
  supported by it (``support_rule`` "parent"); its bottom centre is one of the static's
  ``rest_points``. Containers: openable statics except Toilet.
"""

from __future__ import annotations

import json
import math
import statistics
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from .errors import HomeSpecError, SourceDataError
from .findings import (
    DROPPED_ROOMS,
    LOST_SHARE_PROCTHOR,
    Finding,
    counts_text,
    empty_room,
    lost_grid_points,
)
from .navgrid import GRID_M, farthest_pair
from .room_objects import OPENABLE_NOT_CONTAINER, SUPPORT_RADIUS_M
from .rooms import FLOOR_CONTACT_M, NOT_OBSTACLES
from .vocabulary import SEMI_DYNAMIC_BY_THOR_TYPE, STATIC_BY_THOR_TYPE

PROCTHOR_HOUSES = Path("procthor_houses")
ASSET_DATABASE = Path("ai2thor/procthor_db/asset-database.json")

WALL_CLEARANCE_M = 0.2
FURNITURE_CLEARANCE_M = 0.1
OPENING_MARGIN_M = 0.15
MAX_LINK_M = 0.9

ROOM_NAMES = {
    "Kitchen": "kitchen",
    "LivingRoom": "living",
    "Bedroom": "bedroom",
    "Bathroom": "bathroom",
}

NOTES = (
    "ProcTHOR house: Unity -> ROS REP-103 (x=z_u, y=-x_u, shifted by a multiple of 0.25 m so y >= 0). "
    f"Viewpoints: 0.25 m lattice points inside a room's floor polygon >= {WALL_CLEARANCE_M} m from "
    f"its walls and >= {FURNITURE_CLEARANCE_M} m outside every floor-standing object's rotated "
    "footprint, largest connected piece of the house. Rooms are joined by `links` (steps through "
    f"doorways and open walls, <= {MAX_LINK_M} m, crossing the opening) and walked, not teleported "
    "(`teleport: false`). Starts: the two viewpoints of a room farthest apart by walking distance. "
    "See pipeline/procthor.py."
)

Cell = tuple[int, int]
XY = tuple[float, float]


@dataclass(frozen=True)
class Asset:
    object_type: str
    size: tuple[float, float, float]  # Unity x, y, z (asset axes)
    openable: bool


@cache
def _asset_index(path: Path) -> dict[str, Asset]:
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SourceDataError(
            path, "the ProcTHOR homes (asset types and sizes)", str(exc)
        ) from None
    index: dict[str, Asset] = {}
    for object_type, assets in doc.items():
        for a in assets:
            bb = a["boundingBox"]
            index[a["assetId"]] = Asset(
                object_type,
                (float(bb["x"]), float(bb["y"]), float(bb["z"])),
                "CanOpen" in a.get("secondaryProperties", ()),
            )
    return index


def asset_index(source: Path) -> dict[str, Asset]:
    return _asset_index(source / ASSET_DATABASE)


@dataclass(frozen=True)
class _Obj:
    id: str
    asset: Asset
    center_u: tuple[float, float, float]  # Unity bbox centre
    yaw_deg: float
    parent: str | None

    def footprint_contains(self, xu: float, zu: float, margin: float) -> bool:
        t = math.radians(self.yaw_deg)
        dx, dz = xu - self.center_u[0], zu - self.center_u[2]
        lx = math.cos(t) * dx - math.sin(t) * dz
        lz = math.sin(t) * dx + math.cos(t) * dz
        return (
            abs(lx) <= self.asset.size[0] / 2 + margin
            and abs(lz) <= self.asset.size[2] / 2 + margin
        )

    def aabb_size_u(self) -> tuple[float, float, float]:
        t = math.radians(self.yaw_deg)
        w, h, d = self.asset.size
        c, s = abs(math.cos(t)), abs(math.sin(t))
        return (w * c + d * s, h, w * s + d * c)


def _objects(house: Mapping[str, Any], assets: Mapping[str, Asset], path: Path) -> list[_Obj]:
    out: list[_Obj] = []

    def add(raw: Mapping[str, Any], parent: str | None) -> None:
        asset = assets.get(raw["assetId"])
        if asset is None:
            raise SourceDataError(path, "a ProcTHOR home", f"unknown assetId {raw['assetId']!r}")
        p = raw["position"]
        out.append(
            _Obj(
                raw["id"],
                asset,
                (float(p["x"]), float(p["y"]), float(p["z"])),
                float(raw.get("rotation", {}).get("y", 0.0)),
                parent,
            )
        )

    for raw in house["objects"]:
        add(raw, None)
        for child in raw.get("children", ()):
            add(child, raw["id"])
    return out


def _point_in_polygon(x: float, z: float, poly: Sequence[XY]) -> bool:
    inside = False
    for (x1, z1), (x2, z2) in zip(poly, [*poly[1:], poly[0]], strict=True):
        if (z1 > z) != (z2 > z) and x < x1 + (z - z1) * (x2 - x1) / (z2 - z1):
            inside = not inside
    return inside


def _segment_distance(px: float, pz: float, a: XY, b: XY) -> float:
    ax, az = a
    bx, bz = b
    vx, vz = bx - ax, bz - az
    length2 = vx * vx + vz * vz
    t = 0.0 if length2 == 0 else max(0.0, min(1.0, ((px - ax) * vx + (pz - az) * vz) / length2))
    return math.hypot(px - (ax + t * vx), pz - (az + t * vz))


def _polygon_edges(poly: Sequence[XY]) -> list[tuple[XY, XY]]:
    return list(zip(poly, [*poly[1:], poly[0]], strict=True))


def _wall_segment(wall_id: str) -> tuple[XY, XY]:
    parts = wall_id.split("|")
    x0, z0, x1, z1 = (float(v) for v in parts[-4:])
    return (x0, z0), (x1, z1)


def _crossing(p: XY, q: XY, a: XY, b: XY) -> float | None:
    """Where segment p–q crosses segment a–b, as the distance from a along a–b (None if not)."""
    rx, rz = q[0] - p[0], q[1] - p[1]
    sx, sz = b[0] - a[0], b[1] - a[1]
    den = rx * sz - rz * sx
    if abs(den) < 1e-12:
        return None
    t = ((a[0] - p[0]) * sz - (a[1] - p[1]) * sx) / den
    u = ((a[0] - p[0]) * rz - (a[1] - p[1]) * rx) / den
    if not (0.0 <= t <= 1.0 and 0.0 <= u <= 1.0):
        return None
    return u * math.hypot(sx, sz)


@dataclass(frozen=True)
class _Opening:
    rooms: frozenset[str]
    a: XY  # Unity x, z of the wall's start
    b: XY
    lo: float  # metres along a→b
    hi: float


def _openings(house: Mapping[str, Any]) -> list[_Opening]:
    out: list[_Opening] = []
    for door in house.get("doors", ()):
        if door["room0"] == door["room1"]:
            continue  # the exterior door
        a, b = _wall_segment(door["wall0"])
        xs = [float(v["x"]) for v in door["holePolygon"]]
        out.append(_Opening(frozenset((door["room0"], door["room1"])), a, b, min(xs), max(xs)))
    empty = [w for w in house.get("walls", ()) if w.get("empty")]
    for i, w in enumerate(empty):
        seg = _wall_segment(w["id"])
        for other in empty[i + 1 :]:
            if other["roomId"] != w["roomId"] and {_wall_segment(other["id"])} & {
                seg,
                (seg[1], seg[0]),
            }:
                length = math.dist(*seg)
                out.append(
                    _Opening(frozenset((w["roomId"], other["roomId"])), seg[0], seg[1], 0.0, length)
                )
    return out


def _components(nodes: Iterable[Cell], edges: Mapping[Cell, set[Cell]]) -> list[set[Cell]]:
    todo = set(nodes)
    pieces: list[set[Cell]] = []
    while todo:
        seed = min(todo)
        todo.discard(seed)
        piece, stack = {seed}, [seed]
        while stack:
            c = stack.pop()
            for nb in edges.get(c, ()):
                if nb in todo:
                    todo.discard(nb)
                    piece.add(nb)
                    stack.append(nb)
        pieces.append(piece)
    return sorted(pieces, key=lambda p: (-len(p), min(p)))


def _grid_edges(cells: set[Cell]) -> dict[Cell, set[Cell]]:
    edges: dict[Cell, set[Cell]] = {c: set() for c in cells}
    for i, j in cells:
        for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1)):
            nb = (i + di, j + dj)
            if nb not in cells:
                continue
            if di and dj and ((i + di, j) not in cells or (i, j + dj) not in cells):
                continue
            edges[(i, j)].add(nb)
            edges[nb].add((i, j))
    return edges


@dataclass(frozen=True)
class ProcthorHome:
    """One house converted: the home JSON, and what the conversion found wrong with its rooms."""

    doc: dict[str, Any]
    findings: tuple[Finding, ...]


def build_procthor_home(
    source: Path, name: str, house_file: Path, progress: Callable[[str], None] | None = None
) -> ProcthorHome:
    """The home JSON (``objsearch.home/1`` with ``links`` and ``teleport: false``) of one house."""
    path = source / house_file
    if progress:
        progress(f"home {name}: ProcTHOR {house_file.as_posix()}")
    try:
        house = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SourceDataError(path, f"the ProcTHOR home {name!r}", str(exc)) from None
    assets = asset_index(source)
    objs = _objects(house, assets, path)
    polys: dict[str, list[XY]] = {
        str(r["id"]): [(float(p["x"]), float(p["z"])) for p in r["floorPolygon"]]
        for r in house["rooms"]
    }
    types = {r["id"]: r["roomType"] for r in house["rooms"]}
    unknown = sorted({t for t in types.values() if t not in ROOM_NAMES})
    if unknown:
        raise HomeSpecError(f"{path}: room types {unknown} are not kitchen/living/bed/bathroom")
    max_xu = max(x for poly in polys.values() for x, _ in poly)
    # ROS y = -x_u + shift keeps every y >= 0 and the lattice on multiples of the grid.
    frame = _Frame(math.ceil(max_xu / GRID_M) * GRID_M)
    obstacles = [
        o
        for o in objs
        if o.parent is None
        and o.asset.object_type not in NOT_OBSTACLES
        and o.center_u[1] - o.asset.size[1] / 2 < FLOOR_CONTACT_M
    ]
    room_of, covered = _viewpoints(polys, obstacles, frame)
    edges: dict[Cell, set[Cell]] = {c: set() for c in room_of}
    for rid in polys:
        for c, nbs in _grid_edges({c for c, r in room_of.items() if r == rid}).items():
            edges[c] |= nbs
    links = _door_links(house, room_of, frame)
    for a, b in links:
        edges[a].add(b)
        edges[b].add(a)
    pieces = _components(room_of, edges)
    if not pieces:
        raise HomeSpecError(f"{path}: no viewpoint left in the house")
    keep = pieces[0]
    links = {(a, b) for a, b in links if a in keep and b in keep}
    names = _room_names(polys, types)
    statics, static_room, objects = _placed_objects(objs, polys, names, frame)
    rooms_json: list[dict[str, Any]] = []
    notes: list[str] = []
    findings: list[Finding] = []
    for rid in sorted(polys, key=lambda r: names[r]):
        cells = {c for c in keep if room_of[c] == rid}
        cut_off = sum(r == rid for r in room_of.values()) - len(cells)
        where = f"{house_file.as_posix()}#{rid}"
        ends = sorted({c for link in links for c in link if room_of[c] == rid})
        why = (
            "fewer than 2 reachable viewpoints"
            if len(cells) < 2
            else "no doorway reached"
            if not ends
            else None
        )
        if why is not None:
            notes.append(f"{names[rid]} dropped: {why}")
            findings.append(_dropped(name, names[rid], where, why, cells, covered[rid], cut_off))
            continue
        lost = lost_grid_points(
            name, names[rid], where, len(cells), covered[rid], cut_off, LOST_SHARE_PROCTHOR
        )
        findings += [lost] if lost else []
        room_statics = sorted(
            (s for k, s in statics.items() if static_room[k] == rid), key=lambda s: s["id"]
        )
        empty = empty_room(name, names[rid], where, len(room_statics))
        findings += [empty] if empty else []
        for s in room_statics:
            s["rest_points"] = sorted(s["rest_points"])
        room = _room_json(names[rid], types[rid], where, cells, ends, room_statics, objects[rid])
        rooms_json.append(room)
    kept_rooms = {r["source_scene"].split("#")[1] for r in rooms_json}
    doc = {
        "format": "objsearch.home/1",
        "name": name,
        "grid": GRID_M,
        "notes": NOTES + (" " + "; ".join(notes) if notes else ""),
        "source": house_file.as_posix(),
        "teleport": False,
        "links": sorted(
            [[a[0] * GRID_M, a[1] * GRID_M], [b[0] * GRID_M, b[1] * GRID_M]]
            for a, b in links
            if room_of[a] in kept_rooms and room_of[b] in kept_rooms
        ),
        "rooms": rooms_json,
    }
    return ProcthorHome(doc, tuple(findings))


@dataclass(frozen=True, slots=True)
class _Frame:
    """Unity's floor coordinates (x_u, z_u) and the home's ROS frame: x = z_u, y = shift - x_u."""

    shift: float

    def to_ros(self, xu: float, zu: float) -> XY:
        return (round(zu, 4), round(self.shift - xu, 4))

    def to_unity(self, cell: Cell) -> XY:
        return (self.shift - cell[1] * GRID_M, cell[0] * GRID_M)


def _viewpoints(
    polys: Mapping[str, list[XY]], obstacles: Sequence[_Obj], frame: _Frame
) -> tuple[dict[Cell, str], dict[str, list[str]]]:
    """Each grid point a viewpoint may stand on, with its room; and per room, the type of the
    obstacle over each grid point it covers (not counting the points too near a wall, which no
    room keeps): what the findings report as lost."""
    shift = frame.shift
    room_of: dict[Cell, str] = {}
    covered: dict[str, list[str]] = {rid: [] for rid in polys}
    for rid in sorted(polys):
        poly = polys[rid]
        xs = [x for x, _ in poly]
        zs = [z for _, z in poly]
        for i in range(math.floor(min(zs) / GRID_M), math.ceil(max(zs) / GRID_M) + 1):
            for j in range(
                math.floor((shift - max(xs)) / GRID_M), math.ceil((shift - min(xs)) / GRID_M) + 1
            ):
                xu, zu = frame.to_unity((i, j))
                if not _point_in_polygon(xu, zu, poly):
                    continue
                if any(
                    _segment_distance(xu, zu, a, b) < WALL_CLEARANCE_M
                    for a, b in _polygon_edges(poly)
                ):
                    continue
                blocker = next(
                    (o for o in obstacles if o.footprint_contains(xu, zu, FURNITURE_CLEARANCE_M)),
                    None,
                )
                if blocker is not None:
                    covered[rid].append(blocker.asset.object_type)
                    continue
                room_of[(i, j)] = rid
    return room_of, covered


def _door_links(
    house: Mapping[str, Any], room_of: Mapping[Cell, str], frame: _Frame
) -> set[tuple[Cell, Cell]]:
    """Through each doorway, each viewpoint's shortest link to one on the other side that crosses
    the opening inside its margins."""
    links: set[tuple[Cell, Cell]] = set()
    reach = math.ceil(MAX_LINK_M / GRID_M)
    for op in _openings(house):
        r0, r1 = sorted(op.rooms)
        side0 = [c for c, r in room_of.items() if r == r0]
        side1 = [c for c, r in room_of.items() if r == r1]
        for here, there in ((side0, side1), (side1, side0)):
            there_set = set(there)
            for p in here:
                best: tuple[float, Cell] | None = None
                for di in range(-reach, reach + 1):
                    for dj in range(-reach, reach + 1):
                        q = (p[0] + di, p[1] + dj)
                        if q not in there_set:
                            continue
                        length = GRID_M * math.hypot(di, dj)
                        if length > MAX_LINK_M:
                            continue
                        at = _crossing(frame.to_unity(p), frame.to_unity(q), op.a, op.b)
                        if at is None or not (
                            op.lo + OPENING_MARGIN_M <= at <= op.hi - OPENING_MARGIN_M
                        ):
                            continue
                        if best is None or (length, q) < best:
                            best = (length, q)
                if best is not None:
                    links.add((min(p, best[1]), max(p, best[1])))
    return links


def _room_names(polys: Mapping[str, list[XY]], types: Mapping[str, str]) -> dict[str, str]:
    """Each room's name: its type's, numbered from the second of a type on (``bedroom-2``)."""
    names: dict[str, str] = {}
    counts: dict[str, int] = {}
    for rid in sorted(
        polys, key=lambda r: int(r.split("|")[1]) if r.split("|")[1].isdigit() else 0
    ):
        base = ROOM_NAMES[types[rid]]
        counts[base] = counts.get(base, 0) + 1
        names[rid] = base if counts[base] == 1 else f"{base}-{counts[base]}"
    return names


def _placed_objects(
    objs: Sequence[_Obj], polys: Mapping[str, list[XY]], names: Mapping[str, str], frame: _Frame
) -> tuple[dict[str, dict[str, Any]], dict[str, str], dict[str, list[dict[str, Any]]]]:
    """The static objects (by object id) and their rooms, and each room's semi-dynamic objects
    with what supports them."""

    def room_at(xu: float, zu: float) -> str | None:
        for rid, poly in polys.items():
            if _point_in_polygon(xu, zu, poly):
                return rid
        return None

    statics: dict[str, dict[str, Any]] = {}
    static_room: dict[str, str] = {}
    for o in objs:
        cls = STATIC_BY_THOR_TYPE.get(o.asset.object_type)
        in_room = room_at(o.center_u[0], o.center_u[2])
        if cls is None or in_room is None:
            continue
        rid = in_room
        x, y = frame.to_ros(o.center_u[0], o.center_u[2])
        su = o.aabb_size_u()
        sid = f"{names[rid]}/{o.id}"
        statics[o.id] = {
            "id": sid,
            "thor_type": o.asset.object_type,
            "cls": cls.name,
            "center": [x, y, round(o.center_u[1], 4)],
            "size": [round(su[2], 4), round(su[0], 4), round(su[1], 4)],
            "container": o.asset.openable and o.asset.object_type not in OPENABLE_NOT_CONTAINER,
            "openable": o.asset.openable,
            "rest_points": [],
        }
        static_room[o.id] = rid
    objects: dict[str, list[dict[str, Any]]] = {rid: [] for rid in polys}
    for o in objs:
        if o.parent in statics:
            x, y = frame.to_ros(o.center_u[0], o.center_u[2])
            statics[o.parent]["rest_points"].append(
                [x, y, round(o.center_u[1] - o.asset.size[1] / 2, 4)]
            )
        dyn = SEMI_DYNAMIC_BY_THOR_TYPE.get(o.asset.object_type)
        in_room = room_at(o.center_u[0], o.center_u[2])
        if dyn is None or in_room is None:
            continue
        rid = in_room
        x, y = frame.to_ros(o.center_u[0], o.center_u[2])
        center = (x, y, round(o.center_u[1], 4))
        su = o.aabb_size_u()
        support, rule = None, None
        if o.parent in statics and static_room[o.parent] == rid:
            support, rule = statics[o.parent]["id"], "parent"
        else:
            near = _nearest_static(center, [s for k, s in statics.items() if static_room[k] == rid])
            if near is not None:
                support, rule = near, "nearest"
        inside = bool(
            support and any(s["id"] == support and s["container"] for s in statics.values())
        )
        objects[rid].append(
            {
                "id": f"{names[rid]}/{o.id}",
                "thor_type": o.asset.object_type,
                "cls": dyn.name,
                "center": list(center),
                "size": [round(su[2], 4), round(su[0], 4), round(su[1], 4)],
                "support": support,
                "support_rule": rule,
                "inside": inside,
            }
        )
    return statics, static_room, objects


def _dropped(
    home: str,
    room: str,
    where: str,
    why: str,
    cells: set[Cell],
    covered: Sequence[str],
    cut_off: int,
) -> Finding:
    """The finding of a room dropped from the home, with where its grid points went."""
    blockers = Counter(covered)
    return Finding(
        DROPPED_ROOMS,
        home,
        room,
        where,
        f"dropped ({why}): of its {len(cells) + cut_off + len(covered)} grid "
        f"points {len(covered)} lie inside furniture"
        + (f" [{counts_text(blockers)}]" if blockers else "")
        + f", {cut_off} are cut off from the rest of the house (furniture across "
        f"its doorway?), {len(cells)} are reachable",
    )


def _room_json(
    name: str,
    room_type: str,
    where: str,
    cells: set[Cell],
    ends: Sequence[Cell],
    statics: list[dict[str, Any]],
    objects: list[dict[str, Any]],
) -> dict[str, Any]:
    """One kept room of the home JSON: its viewpoints, door (the doorway ends' median), two
    starts (the farthest pair of viewpoints, each facing the room's middle) and its objects."""
    mx = statistics.median(c[0] for c in ends)
    my = statistics.median(c[1] for c in ends)
    door = min(ends, key=lambda c: (math.hypot(c[0] - mx, c[1] - my), c))
    a, b, _ = farthest_pair(cells)
    cx = statistics.fmean(c[0] for c in cells) * GRID_M
    cy = statistics.fmean(c[1] for c in cells) * GRID_M
    starts = [
        {
            "name": f"{name}-{k}",
            "x": c[0] * GRID_M,
            "y": c[1] * GRID_M,
            "yaw": round(math.atan2(cy - c[1] * GRID_M, cx - c[0] * GRID_M), 4),
        }
        for k, c in enumerate((a, b), start=1)
    ]
    return {
        "name": name,
        "room_type": room_type,
        "source_scene": where,
        "viewpoints": [[c[0] * GRID_M, c[1] * GRID_M] for c in sorted(cells)],
        "door": [door[0] * GRID_M, door[1] * GRID_M],
        "starts": starts,
        "statics": statics,
        "objects": sorted(objects, key=lambda o: o["id"]),
        "alfred_poses": [],
    }


def _nearest_static(
    center: tuple[float, float, float], statics: Sequence[Mapping[str, Any]]
) -> str | None:
    best: tuple[float, str] | None = None
    for s in statics:
        gaps = [
            max(abs(p - c) - z / 2, 0.0)
            for p, c, z in zip(center, s["center"], s["size"], strict=True)
        ]
        d = math.sqrt(sum(g * g for g in gaps))
        sid = str(s["id"])
        if d <= SUPPORT_RADIUS_M and (best is None or (d, sid) < best):
            best = (d, sid)
    return None if best is None else best[1]
