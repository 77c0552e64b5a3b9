"""Schedules whose routines come from the HOMER households (``homer-<seed>``), not from us.

``data/priors/homer_routines.json`` (``pipeline/homer.py``) counts, for each of HOMER's five
simulated households (Patel & Chernova, CoRL 2022) and each object it tracks, where the object
was at each of the seeded schedules' four times of day over the household's days. A
``homer-<seed>`` schedule lays those routines onto one of our homes, once per (home, seed), for
each target class:

- **which routine**: one HOMER (household, object) routine drawn uniformly among those of the
  HOMER objects that are the class (``target_objects``: Apple ← food_apple, Bowl ← bowl, Cup ←
  coffee_cup, drinking_glass, mug), or among every HOMER routine for a class no HOMER household
  has (Laptop, Phone, Pillow, ToiletPaper, Vase: they keep a HOMER object's routine *shape* —
  which times share a place, how often it is elsewhere — on places of their own);
- **which place of ours**: each HOMER place of the routine (a piece of furniture, node by node)
  becomes one static instance of the home, fixed for the schedule: one of the home's statics of
  the mapped type (``place_types``: kitchen_counter → CounterTop, table → DiningTable, …) where
  the class can be placed on that type (the AI2-THOR placement statistics count it there); else
  — a cupboard, a dresser, the TV stand, "outside", or a type the class is never put on — a
  static drawn once from the class's placement statistics, as the other schedules draw. Two
  HOMER places of one routine get two different statics while the home has enough (two HOMER
  counters share the home's one CounterTop).

Then every scene (one slot of one day) draws the class's place from the slot's counts: the
share of HOMER days the object was at each place at that time. Exceptions are HOMER's own;
nothing is added. HOMER has no weekdays and no calendar (its days are independent draws of one
routine), so every day is the same and there is no drift; ``pipeline/homer.py`` says what was
measured. Scenes are times of day as on every seeded schedule (``routine_schedule.scene_clock``),
84 of them (21 days) as ``routine-<seed>``.

:func:`homer_slot_distribution` is the per-scene distribution of a slot as drawn, before the
generator's redraws. The references read where the scenes (:func:`homer_scene`) land, redraws included
(``sim/distribution_oracle.py``).
"""

from __future__ import annotations

import random
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from objsearch.agent.categories import read_json
from objsearch.agent.datapaths import data_key
from objsearch.agent.errors import DataFileError
from objsearch.agent.home import Home
from objsearch.sim.habit_schedule import place_in_scene, sorted_statics
from objsearch.sim.placements import Placement, Placements, Schedule
from objsearch.sim.routine_schedule import ROUTINE_DAYS, SCENES_PER_DAY, SLOT_MINUTES
from objsearch.sim.stats_schedule import PlacementStats, _draw_static, _receptacle_type

ROUTINES_FILE = "priors/homer_routines.json"
HOMER_SCENES = ROUTINE_DAYS * SCENES_PER_DAY


@dataclass(frozen=True, slots=True)
class HomerRoutine:
    """One HOMER object's routine: per slot, (place node id, days there), and the places' HOMER
    classes."""

    household: str
    obj: str
    slots: tuple[tuple[tuple[str, int], ...], ...]
    places: Mapping[str, str]


@dataclass(frozen=True)
class HomerRoutines:
    routines: tuple[HomerRoutine, ...]
    place_types: Mapping[str, str | None]
    target_objects: Mapping[str, tuple[str, ...]]

    @classmethod
    def load(cls, data: Path | None = None) -> HomerRoutines:
        """The routines of the data folder ``data`` (None: ``datapaths.data_dir()``), read once
        per resolved folder in a process."""
        return _homer_routines(data_key(data))

    @classmethod
    def read(cls, folder: Path) -> HomerRoutines:
        path = folder / ROUTINES_FILE
        doc: Any = read_json(path, "the HOMER routines")
        try:
            if tuple(doc["slot_minutes"]) != SLOT_MINUTES:
                raise ValueError(f"slot_minutes {doc['slot_minutes']} are not {SLOT_MINUTES}")
            routines = tuple(
                HomerRoutine(
                    household=str(h["household"]),
                    obj=str(obj),
                    slots=tuple(
                        tuple((str(k), int(v)) for k, v in sorted(counts.items()))
                        for counts in per_slot
                    ),
                    places={str(k): str(v) for k, v in h["places"].items()},
                )
                for h in doc["households"]
                for obj, per_slot in sorted(h["routines"].items())
            )
            return cls(
                routines=routines,
                place_types={str(k): v for k, v in doc["place_types"].items()},
                target_objects={str(k): tuple(v) for k, v in doc["target_objects"].items()},
            )
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise DataFileError(f"{path} is malformed: {exc!r}") from None

    def pool(self, cls: str) -> tuple[HomerRoutine, ...]:
        """The routines a target class draws from: its HOMER counterparts', else all."""
        objects = self.target_objects.get(cls, ())
        mine = tuple(r for r in self.routines if r.obj in objects)
        return mine or self.routines


@cache
def _homer_routines(folder: Path) -> HomerRoutines:
    return HomerRoutines.read(folder)


#: class → per slot, static id → P(there).
SlotTable = dict[str, tuple[dict[str, float], ...]]


@dataclass(frozen=True, slots=True)
class LaidRoutine:
    """A HOMER routine laid onto a home: which one, and each HOMER place's static of ours."""

    routine: HomerRoutine
    statics: Mapping[str, str]


def laid_routines(home: Home, seed: int, data: Path | None = None) -> dict[str, LaidRoutine]:
    """Each placeable class's HOMER routine and its places in ``home``, for (home, seed), from
    the routines and statistics of the data folder ``data`` (None: ``datapaths.data_dir()``)."""
    stats = PlacementStats.load(data)
    homer = HomerRoutines.load(data)
    rng = random.Random(f"homer-schedule:routines:{home.name}:{seed}")
    statics = sorted_statics(home)
    out: dict[str, LaidRoutine] = {}
    for cls in sorted(stats.counts):
        weights = stats.counts[cls]
        routine = rng.choice(homer.pool(cls))
        where: dict[str, str] = {}
        for node in sorted({k for per_slot in routine.slots for k, _ in per_slot}):
            # Two HOMER places stay two places of ours while the home has enough.
            free = [s for s in statics if s.id not in where.values()] or statics
            thor = homer.place_types.get(routine.places[node])
            same = [
                s
                for s in statics
                if thor is not None and _receptacle_type(s) == thor and weights.get(thor, 0) > 0
            ]
            same = [s for s in same if s.id not in where.values()] or same
            chosen = rng.choice(same) if same else _draw_static(rng, weights, free, None)
            if chosen is None:  # no free static takes the class: share one
                chosen = _draw_static(rng, weights, statics, None)
            if chosen is None:
                break
            where[node] = chosen.id
        else:
            out[cls] = LaidRoutine(routine, where)
    return out


def homer_table(home: Home, seed: int, data: Path | None = None) -> SlotTable:
    """class → per slot, static id → P(the object is there in one scene of that slot)
    (``data``: as :func:`laid_routines`)."""
    out: SlotTable = {}
    for cls, laid in laid_routines(home, seed, data).items():
        per_slot = []
        for counts in laid.routine.slots:
            days = sum(n for _, n in counts)
            dist: dict[str, float] = {}
            for node, n in counts:
                sid = laid.statics[node]
                dist[sid] = dist.get(sid, 0.0) + n / days
            per_slot.append(dict(sorted(dist.items())))
        out[cls] = tuple(per_slot)
    return out


def homer_slot_distribution(home: Home, seed: int, slot: int) -> dict[str, dict[str, float]]:
    """class → static id → P(there) in one scene of ``slot``."""
    return {cls: dict(per_slot[slot]) for cls, per_slot in homer_table(home, seed).items()}


def homer_schedule(
    home: Home, seed: int, *, scenes: int | None = None, data: Path | None = None
) -> Schedule:
    """A schedule for ``home`` whose objects keep HOMER households' routines (module doc);
    ``data``: the data folder ``home`` was read from (None: ``datapaths.data_dir()``)."""
    scenes = scenes or HOMER_SCENES
    table = homer_table(home, seed, data)
    rng = random.Random(f"homer-schedule:scenes:{home.name}:{seed}")
    out: dict[int, Placements] = {}
    redrawn = 0
    for scene in range(1, scenes + 1):
        out[scene], refused = homer_scene(rng, home, table, (scene - 1) % SCENES_PER_DAY, data)
        redrawn += refused
    return Schedule(name=f"homer-{seed}", home=home.name, scenes=out, redrawn=redrawn)


def homer_scene(
    rng: random.Random, home: Home, table: SlotTable, slot: int, data: Path | None = None
) -> tuple[Placements, int]:
    """One scene of ``slot``: each class, in class order, drawn from the slot's counts and put
    there, or drawn again while it cannot be seen or its rest points are taken
    (``place_in_scene``; ``data``: the data folder ``home`` was read from); and how many draws
    were refused."""
    stats = PlacementStats.load(data)
    statics = sorted_statics(home)
    placed: dict[str, Placement] = {}
    redrawn = 0
    for cls in sorted(table):
        dist = table[cls][slot]
        places = sorted(dist)
        where = home.statics[rng.choices(places, weights=[dist[p] for p in places])[0]]
        redrawn += place_in_scene(rng, home, cls, stats, statics, where, placed, data)
    return placed, redrawn
