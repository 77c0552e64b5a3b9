"""Placements a camera can see: whether any viewpoint of its room detects a placed object.

A placement is *seeable* when, for every search camera (``sim.world.CAMERAS``), some viewpoint of
its room, facing it with the camera pitched at it (and its container opened, if it lies in one),
shows at least its class's ``min_mask_area_px`` of it with only the room's statics around (other
placements move from scene to scene). Every camera must see it so that both cameras search the same
scenes and neither is given an object it cannot detect from anywhere: the geometric camera's
projected area is not the render's, and a phone flat on a counter can show the occluding camera
100 px and the geometric one 98 px (procthor-04, habit-0 scene 3: a failure no searcher could avoid). Schedules drawn from statistics (stats, habit) redraw an unseeable
placement; schedules of fixed data (Table I, Table II, rearr) keep their data, and a run leaves an
unseeable placement out of its scene (:func:`seeable_scenes`), which the bench reports.

The answer for one placement box is computed once per process (viewpoints nearest the object
first, stopping at the first that detects it) and kept by (home digest, room, box, support,
threshold); the vocabulary the threshold comes from is read once per data folder.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from objsearch.agent.categories import Vocabulary
from objsearch.agent.datapaths import data_key
from objsearch.agent.home import Box, Home
from objsearch.agent.navmap import NavigationMap
from objsearch.sim.placements import Placement, Placements
from objsearch.sim.visibility import OccludingCamera, VisibilityCache
from objsearch.sim.world import CAMERAS, SearchCamera, first_sighting, search_camera


def _checking_camera(name: str) -> SearchCamera:
    if name == "occluding":
        # Its own cache: one view per (placement, viewpoint), never seen again by a search.
        return OccludingCamera(cache=VisibilityCache(max_views=1))
    return search_camera(name)


#: Every search camera, the occluding one (the costly one, and the one that refuses most) first.
_CAMERAS = tuple(_checking_camera(name) for name in CAMERAS)


@dataclass(frozen=True, slots=True)
class Visibility:
    seeable: bool
    #: the detecting view's mask (the last camera's); when not seeable, the largest of any view of
    #: the first camera that detects it from nowhere
    best_mask_px: float


@dataclass(frozen=True, slots=True)
class Unseeable:
    """A placement of fixed data no viewpoint can detect, as the bench reports it."""

    home: str
    scene: int
    cls: str
    instance_id: str
    best_mask_px: float


_NAVMAPS: dict[str, NavigationMap] = {}
_ANSWERS: dict[tuple[str, str, Box, str | None, bool, float], Visibility] = {}


def _navmap(home: Home) -> NavigationMap:
    if home.digest not in _NAVMAPS:
        _NAVMAPS[home.digest] = NavigationMap.from_home(home)
    return _NAVMAPS[home.digest]


@cache
def _vocabulary(folder: Path) -> Vocabulary:
    return Vocabulary.load(data=folder)


def visibility(home: Home, placement: Placement, data: Path | None = None) -> Visibility:
    """Whether, for every search camera, some viewpoint of the placement's room detects it (see the
    module doc), at the mask threshold of the vocabulary of the data folder ``data`` (None:
    ``datapaths.data_dir()``)."""
    threshold = _vocabulary(data_key(data)).classes[placement.cls].min_mask_area_px
    p = placement
    key = (home.digest, p.room, p.box, p.support, p.inside, threshold)
    if key not in _ANSWERS:
        _ANSWERS[key] = _visibility(home, p.room, p.box, p.support, p.inside, threshold)
    return _ANSWERS[key]


def _visibility(
    home: Home, room: str, box: Box, support: str | None, inside: bool, threshold: float
) -> Visibility:
    probe = Placement("probe", "probe", box, room, support, inside)
    nearest_first = sorted(
        _navmap(home).viewpoints(room),
        key=lambda v: ((v.x - box.center[0]) ** 2 + (v.y - box.center[1]) ** 2, v),
    )
    mask = 0.0
    for camera in _CAMERAS:
        seen = first_sighting(camera, home, probe, (probe,), nearest_first, threshold)
        if seen.viewpoint is None:
            return Visibility(False, seen.mask_px)
        mask = seen.mask_px
    return Visibility(True, mask)


def seeable(home: Home, placement: Placement, data: Path | None = None) -> bool:
    return visibility(home, placement, data).seeable


def seeable_scenes(
    home: Home, scenes: Mapping[int, Placements], data: Path | None = None
) -> tuple[dict[int, Placements], tuple[Unseeable, ...]]:
    """The scenes without their unseeable placements, and those placements (thresholds of the
    data folder ``data``'s vocabulary; None: ``datapaths.data_dir()``)."""
    kept: dict[int, Placements] = {}
    dropped: list[Unseeable] = []
    for n, placements in sorted(scenes.items()):
        keep: dict[str, Placement] = {}
        for key, p in sorted(placements.items()):
            v = visibility(home, p, data)
            if v.seeable:
                keep[key] = p
            else:
                dropped.append(
                    Unseeable(home.name, n, p.cls, p.instance_id, round(v.best_mask_px, 1))
                )
        kept[n] = keep
    return kept, tuple(dropped)
