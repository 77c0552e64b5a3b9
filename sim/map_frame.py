"""A new map whose frame moves: the simulated robot's fresh SLAM map.

A session that starts in a new map (``bench homes --new-map-day N --new-map-frame moved``)
gets a map whose frame is a rigid transform of the old one, as a fresh SLAM map would be: its
origin and heading are wherever mapping began. The transform (rotation about z uniform in
[-π, π), translation uniform in ±:data:`SHIFT_M` per axis) is drawn from the run's seed and the
map's id, and recorded in that session's ``run_started.params.map_frame``, so the run replays
exactly; a run that records none keeps the old frame (every run before this one).

The robot then reports in the new map's frame (:class:`MovedMapWorld`): its pose, its routes and
every detection's position, and the new semantic map's statics (same ids, the home's), which the
agent registers to its own frame (agent/map_frames.py).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from objsearch.agent.errors import ObjsearchError
from objsearch.agent.geometry import Point
from objsearch.agent.home import Home
from objsearch.agent.map_frames import InFrame, Rigid2D
from objsearch.sim.world import SimWorld

#: ``new_map_frame`` values: the new map keeps the old frame (the default, as before), or moves.
FRAME_MODES = ("same", "moved")
#: The largest shift of a new map's origin per axis (m): homes span up to about 15 m.
SHIFT_M = 5.0
#: Keeps the frame's draws apart from the detector's and the localiser's.
_STREAM = 0xF4A3E


def frame_mode(params: Mapping[str, Any]) -> str:
    """The run's ``new_map_frame`` (absent: ``same``), validated."""
    mode = str(params.get("new_map_frame") or "same")
    if mode not in FRAME_MODES:
        raise ObjsearchError(
            f"unknown new-map frame {mode!r}; choose from {', '.join(FRAME_MODES)}"
        )
    return mode


def draw_frame(seed: int, map_id: str) -> Rigid2D:
    """The frame of the map ``map_id`` in the run seeded ``seed``, as a transform from the home's
    frame: the same seed and map id give the same frame."""
    key = [int(b) for b in map_id.encode()]
    rng = np.random.default_rng([seed, _STREAM, *key])
    yaw, x, y = (
        rng.uniform(-math.pi, math.pi),
        rng.uniform(-SHIFT_M, SHIFT_M),
        rng.uniform(-SHIFT_M, SHIFT_M),
    )
    return Rigid2D(float(yaw), float(x), float(y))


def recorded_frame(params: Mapping[str, Any]) -> Rigid2D | None:
    """The frame a run's ``params.map_frame`` records (None: the home's frame)."""
    doc = params.get("map_frame")
    if not doc:
        return None
    try:
        return Rigid2D(float(doc["yaw"]), float(doc["x"]), float(doc["y"]))
    except (KeyError, TypeError, ValueError):
        raise ObjsearchError(f"the run's map_frame {doc!r} is not a frame") from None


class MovedMapWorld(InFrame):
    """A simulated world seen in a new map's frame ``frame`` (home frame → map frame), whose
    semantic map puts the home's statics there too."""

    def __init__(self, world: SimWorld, frame: Rigid2D) -> None:
        super().__init__(world, frame, inner=world.navmap)
        self._home: Home = world.home

    def mapped_statics(self) -> dict[str, tuple[str, Point]]:
        return {
            s.id: (s.cls, Point(*self.transform.point(s.box.center[0], s.box.center[1])))
            for s in self._home.statics.values()
        }
