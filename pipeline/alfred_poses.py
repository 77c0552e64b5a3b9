"""ALFRED's receptacle interaction poses, converted and matched to our statics."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from objsearch.agent.geometry import Vec3

from . import navgrid
from .errors import SourceDataError
from .geometry import RoomFrame
from .navgrid import Cell
from .room_objects import Static

# Where an ALFRED receptacle id matches one of our statics (same type, id positions this close).
ALFRED_MATCH_M = 0.5


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


def alfred_poses(
    openable: dict[str, tuple[float, float, float, float]],
    path: Path,
    room: str,
    frame: RoomFrame,
    statics: tuple[Static, ...],
    viewpoints: frozenset[Cell],
) -> tuple[AlfredPose, ...]:
    """Every ALFRED pose of ``path`` (already read into ``openable``) on the home map."""
    static_positions = [(s, _id_position(s.id.split("/", 1)[1])) for s in statics]
    poses = []
    for object_id, (x, z, yaw_deg, horizon) in sorted(openable.items()):
        unity_pos = _id_position(object_id)
        if unity_pos is None:
            raise SourceDataError(
                path,
                f"the ALFRED poses of the {room}",
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
