"""The semantic map: each static object's position loc_s, nearest viewpoint N_s and view angle θ_s.

Paper §5.1: loc_s is the object's centre; N_s the navigable viewpoint closest to it; θ_s the heading
from N_s to loc_s. ``SemanticMap.from_home`` builds it from the home's ground truth;
``objsearch.agent.mapping`` builds it from RGB-D frames and instance masks.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from objsearch.agent.errors import DataFileError
from objsearch.agent.geometry import Point, Vec3, heading, wrap_angle
from objsearch.agent.home import Box, Home
from objsearch.agent.navmap import NavigationMap

SEMMAP_FORMAT = "objsearch.semmap/1"


@dataclass(frozen=True, slots=True)
class MappedStatic:
    id: str
    cls: str
    room: str
    box: Box
    container: bool
    viewpoint: Point  # N_s
    view_yaw: float  # θ_s
    #: loc_s when it is not the box centre: a map built from RGB-D uses the centre of mass of the
    #: object's point cloud (§5.1 (a)), which lies toward the faces the camera saw.
    centroid: Point | None = None

    @property
    def loc(self) -> Point:
        if self.centroid is not None:
            return self.centroid
        return Point(self.box.center[0], self.box.center[1])


@dataclass(frozen=True)
class SemanticMap:
    statics: tuple[MappedStatic, ...]

    @classmethod
    def from_home(cls, home: Home, navmap: NavigationMap) -> SemanticMap:
        mapped = []
        for room in home.rooms:
            for s in room.statics:
                loc = Point(s.box.center[0], s.box.center[1])
                vp = navmap.nearest_viewpoint(loc.x, loc.y, room.name)
                mapped.append(
                    MappedStatic(
                        id=s.id,
                        cls=s.cls,
                        room=room.name,
                        box=s.box,
                        container=s.container,
                        viewpoint=vp,
                        view_yaw=heading(vp, loc),
                    )
                )
        return cls(tuple(mapped))

    def to_json(self) -> dict[str, Any]:
        """The map as ``objsearch.semmap/1`` JSON (see docs/perception.md)."""
        return {
            "format": SEMMAP_FORMAT,
            "statics": [
                {
                    "id": s.id,
                    "class": s.cls,
                    "room": s.room,
                    "loc": [s.loc.x, s.loc.y],
                    "box": {"center": list(s.box.center), "size": list(s.box.size)},
                    "container": s.container,
                    "viewpoint": [s.viewpoint.x, s.viewpoint.y],
                    "view_yaw": s.view_yaw,
                }
                for s in self.statics
            ],
        }

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> SemanticMap:
        if doc.get("format") != SEMMAP_FORMAT:
            raise DataFileError(
                f"not a semantic map (format {doc.get('format')!r}, expected {SEMMAP_FORMAT!r})"
            )
        try:
            return cls(
                tuple(
                    MappedStatic(
                        id=str(s["id"]),
                        cls=str(s["class"]),
                        room=str(s["room"]),
                        box=Box(
                            tuple(float(v) for v in s["box"]["center"]),  # type: ignore[arg-type]
                            tuple(float(v) for v in s["box"]["size"]),  # type: ignore[arg-type]
                        ),
                        container=bool(s["container"]),
                        viewpoint=Point(float(s["viewpoint"][0]), float(s["viewpoint"][1])),
                        view_yaw=float(s["view_yaw"]),
                        centroid=Point(float(s["loc"][0]), float(s["loc"][1])),
                    )
                    for s in doc["statics"]
                )
            )
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise DataFileError(f"semantic map is malformed: {exc!r}") from None

    def in_room(self, room: str) -> tuple[MappedStatic, ...]:
        return tuple(s for s in self.statics if s.room == room)

    def nearest(self, position: Vec3, room: str) -> tuple[MappedStatic, float] | None:
        """The room's static object whose box is closest to a 3-D position, with that distance."""
        best: tuple[float, str, MappedStatic] | None = None
        for s in self.in_room(room):
            d = s.box.distance_to(position)
            if best is None or (d, s.id) < best[:2]:
                best = (d, s.id, s)
        return None if best is None else (best[2], best[0])


@dataclass(frozen=True)
class AlfredAgreement:
    """How our (N_s, θ_s) compare with ALFRED's interaction poses for the same receptacles."""

    matched: int
    unmatched: int
    viewpoint_errors: tuple[float, ...]  # metres between our N_s and ALFRED's pose
    yaw_errors: tuple[float, ...]  # |θ_s − ALFRED yaw|, radians

    def fraction_within(self, metres: float) -> float:
        errs = self.viewpoint_errors
        return sum(e <= metres + 1e-9 for e in errs) / len(errs) if errs else 0.0

    def yaw_fraction_within(self, radians: float) -> float:
        errs = self.yaw_errors
        return sum(e <= radians + 1e-9 for e in errs) / len(errs) if errs else 0.0

    def summary(self) -> dict[str, Any]:
        errs = sorted(self.viewpoint_errors)
        return {
            "matched": self.matched,
            "unmatched": self.unmatched,
            "median_viewpoint_error_m": errs[len(errs) // 2] if errs else None,
            "viewpoint_within_0.25m": round(self.fraction_within(0.25), 3),
            "viewpoint_within_1m": round(self.fraction_within(1.0), 3),
            "yaw_within_45deg": round(self.yaw_fraction_within(math.pi / 4), 3),
        }


def compare_with_alfred(
    home: Home, semmap: SemanticMap, *, match_radius: float = 0.5
) -> AlfredAgreement:
    """Match ALFRED poses to our statics (same AI2-THOR type, nearest centre within match_radius)."""
    thor_type = {s.id: s.thor_type for s in (x for r in home.rooms for x in r.statics)}
    by_room = {room.name: semmap.in_room(room.name) for room in home.rooms}
    vp_errs: list[float] = []
    yaw_errs: list[float] = []
    unmatched = 0
    for room in home.rooms:
        for pose in room.alfred_poses:
            match = _match(pose, by_room[room.name], thor_type, match_radius)
            if match is None:
                unmatched += 1
                continue
            px, py, pyaw = (float(v) for v in pose["pose"])
            vp_errs.append(math.hypot(match.viewpoint.x - px, match.viewpoint.y - py))
            yaw_errs.append(abs(wrap_angle(match.view_yaw - pyaw)))
    return AlfredAgreement(len(vp_errs), unmatched, tuple(vp_errs), tuple(yaw_errs))


def _match(
    pose: Mapping[str, Any],
    statics: tuple[MappedStatic, ...],
    thor_type: Mapping[str, str],
    radius: float,
) -> MappedStatic | None:
    cx, cy = float(pose["center"][0]), float(pose["center"][1])
    best: tuple[float, str, MappedStatic] | None = None
    for s in statics:
        if thor_type.get(s.id) != pose["thor_type"]:
            continue
        d = math.hypot(s.box.center[0] - cx, s.box.center[1] - cy)
        if d <= radius and (best is None or (d, s.id) < best[:2]):
            best = (d, s.id, s)
    return None if best is None else best[2]
