"""Schedules with routines (``routine-<seed>``): where an object is depends on the time of day.

Every seeded schedule's scenes are times of day, four a day (:func:`scene_clock`): scene 1 is
Monday morning, scene 2 Monday afternoon, … scene 5 Tuesday morning. Habit and stats schedules
ignore the hour; here each target class gets, once per (home, seed), drawn from the *same valid
placements* as the stats and habit schedules (a receptacle type weighted by the AI2-THOR
placement counts, then an instance uniformly, ``stats_schedule._draw_static``):

- a **weekday routine**: a usual place per slot (morning, afternoon, evening, night). The
  morning's is a fresh draw; each later slot keeps the slot before's place with ``P_KEEP_SLOT``,
  else it is a fresh draw (a mug goes desk → sink → cupboard; a pillow stays on the bed);
- a **weekend routine**: each slot keeps the weekday place with ``P_WEEKEND_SAME``, else a fresh
  draw (the laptop stays on the sofa on Sundays);
- ``ALTERNATES`` **alternate places** shared by every slot (the exceptions);
- **drift**: at the start of every week after the first (days 8, 15, …), with ``P_DRIFT`` one
  weekday slot of the class (drawn uniformly) gets a fresh usual place — habits change slowly.

Then every scene (one slot of one day) independently:

- with ``P_USUAL`` the object is at the slot's usual place (weekday or weekend routine),
- with ``P_LATE`` at the usual place of the slot before (the routine runs late; in the
  morning, the morning's own),
- with ``P_ALTERNATE`` at one of the alternates (uniformly),
- with ``P_ANYWHERE`` at a fresh draw from the stats distribution over *all* valid statics.

The parameters were fixed before any run (docs/results-routine.md, "Protocol") and are not tuned.
They are not derived from a routine dataset; ``homer-<seed>`` (``sim/homer_schedule.py``) draws
from routines measured in the HOMER households (Patel & Chernova) instead. :func:`routine_distribution`
is the per-scene distribution of one slot and day type for the routines in force on a given day,
as drawn, before the generator's redraws of places that cannot be seen or whose rest points are
taken; the references read where the scenes (:func:`routine_scene`) land, redraws included
(``sim/distribution_oracle.py``).
"""

from __future__ import annotations

import random
from collections.abc import Mapping
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

from objsearch.agent.catalogue import DayClock
from objsearch.agent.home import Home
from objsearch.sim.habit_schedule import (
    draw_alternates,
    draw_place,
    place_in_scene,
    sorted_statics,
    stats_distribution,
)
from objsearch.sim.placements import Placement, Placements, Schedule
from objsearch.sim.stats_schedule import PlacementStats, _draw_static

#: The scenes' times of day (minutes after midnight), one per slot: morning, afternoon,
#: evening, night. Every seeded schedule's scene n is slot (n − 1) mod 4 of day (n − 1) // 4.
SLOT_MINUTES = (7 * 60 + 30, 13 * 60, 18 * 60 + 30, 22 * 60 + 30)
SLOT_NAMES = ("morning", "afternoon", "evening", "night")
SCENES_PER_DAY = len(SLOT_MINUTES)
#: Days of a routine schedule: two weeks to learn from, one to evaluate on.
ROUTINE_DAYS = 21
P_USUAL = 0.7
P_LATE = 0.05
P_ALTERNATE = 0.15
P_ANYWHERE = 0.1
ALTERNATES = 2
P_KEEP_SLOT = 0.25
P_WEEKEND_SAME = 0.5
P_DRIFT = 0.5
#: Day 0 is a Monday; days 5 and 6 of each week are the weekend.
WEEKEND = (5, 6)


def scene_clock(scene: int) -> DayClock:
    """The time of day of a seeded schedule's scene (1-based)."""
    day, slot = divmod(scene - 1, SCENES_PER_DAY)
    return DayClock(weekday=day % 7, minute=SLOT_MINUTES[slot])


def scene_day(scene: int) -> int:
    """The 0-based day of a seeded schedule's scene."""
    return (scene - 1) // SCENES_PER_DAY


@dataclass(frozen=True, slots=True)
class Routine:
    """Where one class usually is in each slot, on weekdays and at the weekend, and where it
    sometimes is."""

    weekday: tuple[str, ...]
    weekend: tuple[str, ...]
    alternates: tuple[str, ...]

    def usual(self, weekend: bool, slot: int) -> str:
        return (self.weekend if weekend else self.weekday)[slot]


def routines(home: Home, seed: int, data: Path | None = None) -> dict[str, Routine]:
    """Each placeable class's routine on day 0, for (home, seed), from the placement statistics
    of the data folder ``data`` (None: ``datapaths.data_dir()``)."""
    stats = PlacementStats.load(data)
    rng = random.Random(f"routine-schedule:routines:{home.name}:{seed}")
    statics = sorted_statics(home)
    out: dict[str, Routine] = {}
    for cls in sorted(stats.counts):
        draw = partial(_draw_static, rng, stats.counts[cls], statics, None)
        first = draw()
        if first is None:
            continue
        weekday = [first.id]
        for _ in range(1, SCENES_PER_DAY):
            keep = rng.random() < P_KEEP_SLOT
            fresh = draw()
            weekday.append(weekday[-1] if keep or fresh is None else fresh.id)
        weekend = []
        for place in weekday:
            same = rng.random() < P_WEEKEND_SAME
            fresh = draw()
            weekend.append(place if same or fresh is None else fresh.id)
        taken = set(weekday) | set(weekend)
        alternates = draw_alternates(rng, stats.counts[cls], statics, taken, ALTERNATES)
        out[cls] = Routine(tuple(weekday), tuple(weekend), alternates)
    return out


def routines_by_week(
    home: Home, seed: int, weeks: int, data: Path | None = None
) -> list[dict[str, Routine]]:
    """The routines in force in each week (``weeks`` of them): week 0's, then each drifted
    (``data``: as :func:`routines`)."""
    stats = PlacementStats.load(data)
    rng = random.Random(f"routine-schedule:drift:{home.name}:{seed}")
    statics = sorted_statics(home)
    table = routines(home, seed, data)
    out = [table]
    for _ in range(1, weeks):
        table = dict(table)
        for cls in sorted(table):
            drifts = rng.random() < P_DRIFT
            slot = rng.randrange(SCENES_PER_DAY)
            fresh = _draw_static(rng, stats.counts[cls], statics, None)
            if drifts and fresh is not None:
                weekday = list(table[cls].weekday)
                weekday[slot] = fresh.id
                table[cls] = replace(table[cls], weekday=tuple(weekday))
        out.append(table)
    return out


def routine_distribution(
    home: Home, table: Mapping[str, Routine], weekend: bool, slot: int
) -> dict[str, dict[str, float]]:
    """class → static id → P(there) in one scene of ``slot`` on a weekday or weekend day."""
    stats = PlacementStats.load()
    statics = sorted_statics(home)
    out: dict[str, dict[str, float]] = {}
    for cls, routine in table.items():
        dist = {
            sid: P_ANYWHERE * p for sid, p in stats_distribution(stats.counts[cls], statics).items()
        }
        usual = routine.usual(weekend, slot)
        late = routine.usual(weekend, max(slot - 1, 0))
        dist[usual] = dist.get(usual, 0.0) + P_USUAL
        dist[late] = dist.get(late, 0.0) + P_LATE
        for k in range(ALTERNATES):
            where = routine.alternates[k] if k < len(routine.alternates) else usual
            dist[where] = dist.get(where, 0.0) + P_ALTERNATE / ALTERNATES
        out[cls] = dist
    return out


def routine_schedule(
    home: Home, seed: int, *, scenes: int | None = None, data: Path | None = None
) -> Schedule:
    """A schedule for ``home`` where objects keep routines (see the module doc); ``data``: the
    data folder ``home`` was read from (None: ``datapaths.data_dir()``)."""
    scenes = scenes or ROUTINE_DAYS * SCENES_PER_DAY
    rng = random.Random(f"routine-schedule:scenes:{home.name}:{seed}")
    weekly = routines_by_week(home, seed, scene_day(scenes) // 7 + 1, data)
    out: dict[int, Placements] = {}
    redrawn = 0
    for scene in range(1, scenes + 1):
        day = scene_day(scene)
        slot = (scene - 1) % SCENES_PER_DAY
        table, weekend = weekly[day // 7], day % 7 in WEEKEND
        out[scene], refused = routine_scene(rng, home, table, weekend, slot, data)
        redrawn += refused
    return Schedule(name=f"routine-{seed}", home=home.name, scenes=out, redrawn=redrawn)


def routine_scene(
    rng: random.Random,
    home: Home,
    table: Mapping[str, Routine],
    weekend: bool,
    slot: int,
    data: Path | None = None,
) -> tuple[Placements, int]:
    """One scene of ``slot`` on a weekday or weekend day under ``table``'s routines: each class,
    in class order, drawn as the module doc says and put there (``place_in_scene``: drawn again
    while it cannot be seen or its rest points are taken); and how many draws were refused.
    ``data``: the data folder ``home`` was read from (None: ``datapaths.data_dir()``)."""
    stats = PlacementStats.load(data)
    statics = sorted_statics(home)
    placed: dict[str, Placement] = {}
    redrawn = 0
    for cls in sorted(table):
        routine = table[cls]
        anywhere = partial(_draw_static, rng, stats.counts[cls], statics, None)
        usual = (
            (P_USUAL, routine.usual(weekend, slot)),
            (P_LATE, routine.usual(weekend, max(slot - 1, 0))),
        )
        where = draw_place(rng, usual, P_ALTERNATE, routine.alternates, anywhere, home.statics)
        assert where is not None  # the usual places were drawn from the same statics
        redrawn += place_in_scene(rng, home, cls, stats, statics, where, placed, data)
    return placed, redrawn
