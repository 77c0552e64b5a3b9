"""Placement schedules drawn from AI2-THOR's own placement statistics, with a seed.

``data/priors/ai2thor_placements.json`` (derived by ``objsearch data build`` from ProcTHOR's
``receptacles.json``) counts how often each target type was placed on each receptacle type over the
iTHOR/RoboTHOR scenes. A schedule of ``SCENES`` scenes for a home is drawn as follows:

- scene 1: for every target class, a receptacle *type* is drawn among the home's static objects with
  weight = that count (a type the home lacks, or that is not one of our static classes, cannot be
  drawn: the agent could never look there), then an instance of that type uniformly; a class with no
  possible receptacle in the home is left out of the schedule;
- later scenes: each object moves with probability ``move_rate`` (21 of 72 in the paper's Table II)
  and is then redrawn the same way among the other instances;
- the object rests on one of the static's ``rest_points`` (where AI2-THOR put objects on it; the box
  top centre if none), raised by half its height; in a container it sits at the box centre;
- a placement no viewpoint of its room can see (``sim/seeable.py``: a phone flat on a counter at
  the camera's height) is drawn again, receptacle and spot, from the same ``random.Random``; the
  schedule counts the redraws (``Schedule.redrawn``). After ``MAX_DRAWS`` refusals the object
  stays where it was (in scene 1: is left out).

Object sizes are the median AI2-THOR asset sizes of the class. Everything is drawn from one
``random.Random`` seeded by (home, seed), so a seed names one schedule.
"""

from __future__ import annotations

import random
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import cache, partial
from pathlib import Path
from typing import Any

from objsearch.agent.categories import read_json
from objsearch.agent.datapaths import data_key
from objsearch.agent.errors import DataFileError
from objsearch.agent.home import Box, Home, StaticObject, home_path
from objsearch.sim.placements import Placement, Placements, Schedule
from objsearch.sim.seeable import seeable

SCENES = 10
#: Draws of one placement before the object stays where it was (see the module doc).
MAX_DRAWS = 20
PLACEMENTS_FILE = "priors/ai2thor_placements.json"
#: AI2-THOR names a basin as its own receptacle type; the statistics count the fixture.
_RECEPTACLE_ALIAS = {"SinkBasin": "Sink", "BathtubBasin": "Bathtub"}


@dataclass(frozen=True)
class PlacementStats:
    counts: Mapping[str, Mapping[str, float]]  # class → receptacle type → count
    sizes: Mapping[str, tuple[float, float, float]]  # class → box size (ROS)
    move_rate: float

    @classmethod
    def load(cls, data: Path | None = None) -> PlacementStats:
        """The statistics of the data folder ``data`` (None: ``datapaths.data_dir()``), read once
        per resolved folder in a process."""
        return _placement_stats(data_key(data))


@cache
def _placement_stats(folder: Path) -> PlacementStats:
    path = folder / PLACEMENTS_FILE
    doc = read_json(path, "the AI2-THOR placement statistics")
    try:
        return PlacementStats(
            counts={c: dict(v) for c, v in doc["counts"].items()},
            sizes={c: (float(s[0]), float(s[1]), float(s[2])) for c, s in doc["sizes"].items()},
            move_rate=float(doc["move_rate"]),
        )
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise DataFileError(f"{path} is malformed: {exc!r}") from None


def rest_points(
    home_name: str, data: Path | None = None
) -> dict[str, tuple[tuple[float, float, float], ...]]:
    """Static id → where AI2-THOR put objects on it, from home ``home_name``'s file in the data
    folder ``data`` (None: ``datapaths.data_dir()``); read once per (resolved folder, home)."""
    return _rest_points(home_name, data_key(data))


@cache
def _rest_points(home_name: str, folder: Path) -> dict[str, tuple[tuple[float, float, float], ...]]:
    doc: Any = read_json(home_path(home_name, folder), "a home")
    return {
        s["id"]: tuple((float(p[0]), float(p[1]), float(p[2])) for p in s.get("rest_points", ()))
        for r in doc["rooms"]
        for s in r["statics"]
    }


def _receptacle_type(s: StaticObject) -> str:
    return _RECEPTACLE_ALIAS.get(s.thor_type, s.thor_type)


def _draw_static(
    rng: random.Random,
    weights: Mapping[str, float],
    statics: Sequence[StaticObject],
    exclude: str | None,
) -> StaticObject | None:
    by_type: dict[str, list[StaticObject]] = {}
    for s in statics:
        if s.id != exclude and weights.get(_receptacle_type(s), 0) > 0:
            by_type.setdefault(_receptacle_type(s), []).append(s)
    if not by_type:
        return None
    types = sorted(by_type)
    chosen = rng.choices(types, weights=[weights[t] for t in types])[0]
    return rng.choice(sorted(by_type[chosen], key=lambda s: s.id))


def _free(
    rest: tuple[float, float, float],
    size: tuple[float, float, float],
    taken: Sequence[Placement],
    s: StaticObject,
) -> bool:
    """Whether an object of ``size`` at a rest point of ``s`` overlaps no object already there
    (two objects drawn onto one spot lie inside each other, the one hiding the other)."""
    return not any(
        o.support == s.id
        and abs(o.box.center[0] - rest[0]) < (o.box.size[0] + size[0]) / 2
        and abs(o.box.center[1] - rest[1]) < (o.box.size[1] + size[1]) / 2
        for o in taken
    )


def _place(
    rng: random.Random,
    home: Home,
    cls: str,
    size: tuple[float, float, float],
    s: StaticObject,
    taken: Sequence[Placement] = (),
    data: Path | None = None,
) -> Placement | None:
    """An object of ``cls`` on (or in) ``s`` at a free rest point (of ``home``'s file in the data
    folder ``data``); None when every rest point of ``s`` is under another object."""
    if s.container:
        center = s.box.center
    else:
        # A static without recorded rest points has one: the middle of its top.
        rests = rest_points(home.name, data).get(s.id) or (
            (s.box.center[0], s.box.center[1], s.box.top),
        )
        free = [r for r in rests if _free(r, size, taken, s)]
        if not free:
            return None
        x, y, z = rng.choice(free) if len(free) > 1 else free[0]
        center = (x, y, z + size[2] / 2)
    return Placement(f"{cls}|schedule", cls, Box(center, size), s.room, s.id, s.container)


def place_seeable(
    rng: random.Random,
    home: Home,
    cls: str,
    size: tuple[float, float, float],
    first: StaticObject | None,
    redraw: Callable[[], StaticObject | None],
    taken: Sequence[Placement] = (),
    data: Path | None = None,
) -> tuple[Placement | None, int]:
    """A placement on ``first`` or, while the one drawn is unseeable or has no free rest point,
    on ``redraw()``; and how many draws were refused. None when nothing could be drawn or every draw was refused.
    ``taken``: the objects already placed in the scene, whose rest points are not drawn again;
    ``data``: the data folder ``home`` was read from (None: ``datapaths.data_dir()``)."""
    s = first
    for refused in range(MAX_DRAWS):
        if s is None:
            return None, refused
        p = _place(rng, home, cls, size, s, taken, data)
        if p is not None and seeable(home, p, data):
            return p, refused
        s = redraw()
    return None, MAX_DRAWS


def stats_schedule(
    home: Home, seed: int, *, scenes: int = SCENES, data: Path | None = None
) -> Schedule:
    """A schedule for ``home`` drawn from the placement statistics (see the module doc) of the
    data folder ``data`` (None: ``datapaths.data_dir()``), which ``home`` was read from."""
    stats = PlacementStats.load(data)
    rng = random.Random(f"stats-schedule:{home.name}:{seed}")
    statics = sorted(home.statics.values(), key=lambda s: s.id)
    current: dict[str, Placement] = {}
    out: dict[int, Placements] = {}
    redrawn = 0
    for scene in range(1, scenes + 1):
        for cls in sorted(stats.counts):
            old = current.get(cls)
            if old is not None and rng.random() >= stats.move_rate:
                continue
            draw = partial(
                _draw_static, rng, stats.counts[cls], statics, old.support if old else None
            )
            others = [p for c, p in current.items() if c != cls]
            size = stats.sizes[cls]
            p, refused = place_seeable(rng, home, cls, size, draw(), draw, others, data)
            redrawn += refused
            if p is not None:
                current[cls] = p
        out[scene] = {p.instance_id: p for p in current.values()}
    return Schedule(name=f"stats-{seed}", home=home.name, scenes=out, redrawn=redrawn)
