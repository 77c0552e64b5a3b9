"""Schedules with a past: every object has habits (``habit-<seed>``).

Stats schedules redraw placements independently, so across days there is nothing to remember but
the distribution. Here each target class gets, once per (home, seed), drawn from the *same valid
placements* the stats schedules use (a receptacle type weighted by the AI2-THOR placement counts,
then an instance uniformly, ``stats_schedule._draw_static``):

- a **usual place** (one static instance),
- ``ALTERNATES`` **alternate places** (other instances, drawn the same way without repeats),

and then, every scene independently:

- with ``P_USUAL`` the object is at its usual place,
- with ``P_ALTERNATE`` at one of the alternates (uniformly),
- with ``P_ANYWHERE`` at a fresh draw from the stats distribution over *all* valid statics.

``moved-<seed>`` is the same schedule until scene ``MOVE_SCENE`` (the same draws, scene for scene),
from which on every class has new habits: a usual place in *another room* than before and new
alternates (:func:`moved_habits`) — a household that rearranged itself on one day.

The parameters were fixed before any run (docs/results.md, "Schedules with a past") and are not
tuned. If a home has too few valid statics for two alternates, an alternate's share goes to the
usual place. :func:`habit_distribution` is that per-scene distribution (the distribution oracle's
knowledge); it is exact, because scenes are independent given the habits — but for placements no
viewpoint can see (``sim/seeable.py``), which are drawn again from the fresh-draw distribution as
stats schedules do (``stats_schedule.place_seeable``) and counted in ``Schedule.redrawn``.
"""

from __future__ import annotations

import random
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from objsearch.agent.home import Home, StaticObject
from objsearch.sim.placements import Placement, Placements, Schedule
from objsearch.sim.stats_schedule import (
    PlacementStats,
    _draw_static,
    _receptacle_type,
    place_seeable,
)

#: Scenes of a habit schedule: long enough to learn from.
HABIT_SCENES = 30
P_USUAL = 0.7
P_ALTERNATE = 0.2
P_ANYWHERE = 0.1
ALTERNATES = 2
#: The first scene of ``moved-<seed>`` with the new habits (fixed before any run).
MOVE_SCENE = 11


@dataclass(frozen=True, slots=True)
class Habit:
    """Where one class usually is, and where it sometimes is."""

    usual: str
    alternates: tuple[str, ...]


def sorted_statics(home: Home) -> list[StaticObject]:
    """The home's static instances in id order (the order every seeded draw walks)."""
    return sorted(home.statics.values(), key=lambda s: s.id)


def draw_place(
    rng: random.Random,
    usual: Sequence[tuple[float, str]],
    p_alternate: float,
    alternates: Sequence[str],
    anywhere: Callable[[], StaticObject | None],
    by_id: Mapping[str, StaticObject],
) -> StaticObject | None:
    """One scene's place of one object: each of ``usual`` (probability, static id) in turn, then
    one of ``ALTERNATES`` alternates with ``p_alternate`` in all (uniformly; a missing alternate
    is the first usual place), else a fresh draw, ``anywhere()``. One ``rng.random()`` decides,
    and one ``rng.randrange`` picks the alternate."""
    u = rng.random()
    bound = 0.0
    for p, place in usual:
        bound += p
        if u < bound:
            return by_id[place]
    if u < bound + p_alternate:
        k = rng.randrange(ALTERNATES)
        return by_id[alternates[k] if k < len(alternates) else usual[0][1]]
    return anywhere()


def draw_alternates(
    rng: random.Random,
    weights: Mapping[str, float],
    statics: Sequence[StaticObject],
    taken: set[str],
    count: int,
) -> tuple[str, ...]:
    """Up to ``count`` more places drawn as the usual one was, none of ``taken`` and no repeats
    (fewer when the home has no more valid statics)."""
    taken = set(taken)
    alternates: list[str] = []
    for _ in range(count):
        alt = _draw_static(rng, weights, [s for s in statics if s.id not in taken], None)
        if alt is None:
            break
        taken.add(alt.id)
        alternates.append(alt.id)
    return tuple(alternates)


def place_in_scene(
    rng: random.Random,
    home: Home,
    cls: str,
    stats: PlacementStats,
    statics: Sequence[StaticObject],
    where: StaticObject,
    placed: dict[str, Placement],
    data: Path | None = None,
) -> int:
    """Put ``cls`` on ``where`` in a scene's ``placed`` objects, drawn anew from the stats
    distribution while no viewpoint sees it (``place_seeable``; ``data``: the data folder
    ``home`` was read from); how many draws were refused."""
    anywhere = partial(_draw_static, rng, stats.counts[cls], statics, None)
    taken = list(placed.values())
    p, refused = place_seeable(rng, home, cls, stats.sizes[cls], where, anywhere, taken, data)
    if p is not None:
        placed[p.instance_id] = p
    return refused


def habits(home: Home, seed: int, data: Path | None = None) -> dict[str, Habit]:
    """Each placeable class's usual place and alternates for (home, seed), from the placement
    statistics of the data folder ``data`` (None: ``datapaths.data_dir()``)."""
    stats = PlacementStats.load(data)
    rng = random.Random(f"habit-schedule:habits:{home.name}:{seed}")
    statics = sorted_statics(home)
    out: dict[str, Habit] = {}
    for cls in sorted(stats.counts):
        usual = _draw_static(rng, stats.counts[cls], statics, None)
        if usual is None:
            continue
        alternates = draw_alternates(rng, stats.counts[cls], statics, {usual.id}, ALTERNATES)
        out[cls] = Habit(usual.id, alternates)
    return out


def moved_habits(home: Home, seed: int, data: Path | None = None) -> dict[str, Habit]:
    """The habits of ``moved-<seed>`` from ``MOVE_SCENE`` on: each class's usual place drawn
    among the statics of the rooms other than its old usual place's (kept if there is none),
    alternates drawn as before among the rest (``data``: as :func:`habits`)."""
    stats = PlacementStats.load(data)
    rng = random.Random(f"moved-schedule:habits:{home.name}:{seed}")
    statics = sorted_statics(home)
    out: dict[str, Habit] = {}
    for cls, old in habits(home, seed, data).items():
        old_room = home.statics[old.usual].room
        elsewhere = [s for s in statics if s.room != old_room]
        usual = _draw_static(rng, stats.counts[cls], elsewhere, None)
        if usual is None:
            out[cls] = old
            continue
        alternates = draw_alternates(rng, stats.counts[cls], statics, {usual.id}, ALTERNATES)
        out[cls] = Habit(usual.id, alternates)
    return out


def stats_distribution(
    weights: Mapping[str, float], statics: Sequence[StaticObject]
) -> dict[str, float]:
    """P(static instance) of one ``_draw_static`` draw: a type by its count, an instance uniformly."""
    by_type: dict[str, list[str]] = {}
    for s in statics:
        if weights.get(_receptacle_type(s), 0) > 0:
            by_type.setdefault(_receptacle_type(s), []).append(s.id)
    total = sum(weights[t] for t in by_type)
    return {sid: weights[t] / total / len(ids) for t, ids in sorted(by_type.items()) for sid in ids}


def habit_distribution(
    home: Home, seed: int, table: Mapping[str, Habit] | None = None
) -> dict[str, dict[str, float]]:
    """class → static id → P(the object is there in any one scene) under ``table`` (default: the
    habits of ``habit-<seed>``)."""
    stats = PlacementStats.load()
    statics = sorted_statics(home)
    out: dict[str, dict[str, float]] = {}
    for cls, habit in (table if table is not None else habits(home, seed)).items():
        dist = {
            sid: P_ANYWHERE * p for sid, p in stats_distribution(stats.counts[cls], statics).items()
        }
        share = P_ALTERNATE / ALTERNATES
        dist[habit.usual] = dist.get(habit.usual, 0.0) + P_USUAL
        for k in range(ALTERNATES):
            where = habit.alternates[k] if k < len(habit.alternates) else habit.usual
            dist[where] = dist.get(where, 0.0) + share
        out[cls] = dist
    return out


def habit_schedule(
    home: Home,
    seed: int,
    *,
    scenes: int = HABIT_SCENES,
    moved: bool = False,
    data: Path | None = None,
) -> Schedule:
    """A schedule for ``home`` where objects keep habits; with ``moved``, new habits from
    ``MOVE_SCENE`` on (see the module doc). ``data``: the data folder ``home`` was read from,
    whose statistics and rest points it is drawn with (None: ``datapaths.data_dir()``)."""
    stats = PlacementStats.load(data)
    rng = random.Random(f"habit-schedule:scenes:{home.name}:{seed}")
    statics = sorted_statics(home)
    by_id = home.statics
    before = habits(home, seed, data)
    after = moved_habits(home, seed, data) if moved else before
    out: dict[int, Placements] = {}
    redrawn = 0
    for scene in range(1, scenes + 1):
        table = after if scene >= MOVE_SCENE else before
        placed: dict[str, Placement] = {}
        for cls in sorted(table):
            habit = table[cls]
            anywhere = partial(_draw_static, rng, stats.counts[cls], statics, None)
            usual = ((P_USUAL, habit.usual),)
            where = draw_place(rng, usual, P_ALTERNATE, habit.alternates, anywhere, by_id)
            assert where is not None  # the usual place was drawn from the same statics
            redrawn += place_in_scene(rng, home, cls, stats, statics, where, placed, data)
        out[scene] = placed
    name = f"{'moved' if moved else 'habit'}-{seed}"
    return Schedule(name=name, home=home.name, scenes=out, redrawn=redrawn)
