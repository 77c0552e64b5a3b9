"""A REFERENCE searcher's knowledge, never a robot's: the distribution a schedule draws from.

:class:`DistributionOracle` is a relation model (``RelationSpec("dist-oracle")``) that, on
``run_started``, reads the run's home and schedule and values each static instance by the
probability that the schedule's generator puts the target there in a scene — nothing of today's
draw — conditioned, as a learning strategy may be, on what the robot saw earlier in the same scene
(:class:`~objsearch.agent.belief.Today`: sightings, and looks that did not see the target). It is
the best any memory of the schedule could learn, so a strategy's searches can be read as regret
against it. It learns nothing across scenes.

- ``habit-<seed>``: the exact per-scene distribution (:func:`habit_distribution`);
- ``moved-<seed>``: the same before ``MOVE_SCENE``, the new habits' from then on (it knows the day
  of the move: a reference, not a robot);
- ``routine-<seed>``: the time-BLIND distribution — the routine's per-scene distribution
  averaged over the week's slots and days (:func:`time_blind_distribution`) for the routines in force
  that week (it knows the days of the drift, not the hour): the best a memory that ignores the
  time of day could learn;
- ``homer-<seed>``: likewise the average of the HOMER routines' four slots, as the scenes land
  (below; every day is the same, nothing drifts);
- ``stats-<seed>`` / ``rearr-<seed>``'s stats fallback: the first scene's draw; each later scene
  keeps the object with probability 1 − m (the move rate) and otherwise draws it again among the
  *other* places, so once the robot has seen the object at place j in scene n₀, scene n's
  distribution is e_j·Pⁿ⁻ⁿ⁰ with P = (1 − m)·I + m·K, K(j, s) = q(s) / (1 − q(j)) for s ≠ j; an
  object not seen yet is at q·Pⁿ⁻¹ (:func:`chain`). Without this the "reference" lost to a memory
  that simply remembers yesterday.

Every distribution is the one *after* the generators' redraws (``stats_schedule.place_seeable``,
which every schedule's ``place_in_scene`` calls: a place no viewpoint sees, or whose rest points
are all under objects placed before, is drawn again from the fresh draw). Habit, moved and stats
schedules in closed form: a placement on static s is kept with the share v(s) of its rest points
a viewpoint sees (:func:`seeable_shares`), and a refused one is drawn again from the fresh draw,
so P(s) = d(s)·v(s) + (Σ_t d(t)·(1 − v(t)))·q_v(s), q_v ∝ q·v (:func:`after_redraws`); left out,
both rare there: two objects drawn onto one rest point, and an object left where it was after
``MAX_DRAWS`` refusals. The routine kinds (``routine``, ``homer``) give several classes the same
usual places (HOMER: every HOMER kitchen counter is the home's one CounterTop), so a class often
finds every rest point taken by a class placed before it in the scene — not rare there (on
``homer-0`` of ``ithor-02`` 89 of 672 placements land where the routine never puts them), and it
has no closed form: their references read where the generator's own scene rule lands each class
over ``REFERENCE_SCENES`` scenes per slot and day type drawn from a seed of their own, with the
closed form as a prior worth one scene (:func:`time_of_day_distribution`; the time-blind one is its average,
:func:`time_blind_distribution`).
"""

from __future__ import annotations

import random
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from types import MappingProxyType
from typing import Any, ClassVar

from objsearch.agent.belief import Today
from objsearch.agent.catalogue import RunStarted, SceneGraphSeeded, TaskStarted, decode
from objsearch.agent.datapaths import data_key
from objsearch.agent.home import Box, Home, load_home
from objsearch.agent.scene_graph import Pair
from objsearch.events.projection import EventView
from objsearch.sim.habit_schedule import (
    MOVE_SCENE,
    habit_distribution,
    moved_habits,
    sorted_statics,
    stats_distribution,
)
from objsearch.sim.homer_schedule import homer_scene, homer_slot_distribution, homer_table
from objsearch.sim.placements import Placement
from objsearch.sim.routine_schedule import (
    SCENES_PER_DAY,
    WEEKEND,
    routine_distribution,
    routine_scene,
    routines_by_week,
    scene_day,
)
from objsearch.sim.schedule_names import ROUTINE_KINDS, parse_seeded
from objsearch.sim.seeable import seeable
from objsearch.sim.stats_schedule import PlacementStats, _receptacle_type, rest_points

#: (resolved data folder, home name, class) → :func:`seeable_shares`: a slot oracle reads one
#: distribution per slot.
_SHARES: dict[tuple[Path, str, str], dict[str, float]] = {}


def seeable_shares(home: Home, cls: str) -> dict[str, float]:
    """Static id → the share of its rest points at which a ``cls`` object is seeable (1 for a
    container: the object lies at its centre), for the statics the class can be drawn onto."""
    key = (data_key(), home.name, cls)
    if key not in _SHARES:
        _SHARES[key] = _seeable_shares(home, cls)
    return dict(_SHARES[key])


def _seeable_shares(home: Home, cls: str) -> dict[str, float]:
    stats = PlacementStats.load()
    size = stats.sizes[cls]
    shares: dict[str, float] = {}
    for s in sorted(home.statics.values(), key=lambda s: s.id):
        if stats.counts[cls].get(_receptacle_type(s), 0) <= 0:
            continue
        if s.container:
            centres = [s.box.center]
        else:
            rests = rest_points(home.name).get(s.id) or (
                (s.box.center[0], s.box.center[1], s.box.top),
            )
            centres = [(x, y, z + size[2] / 2) for x, y, z in rests]
        kept = sum(
            seeable(
                home, Placement(f"{cls}|schedule", cls, Box(c, size), s.room, s.id, s.container)
            )
            for c in centres
        )
        shares[s.id] = kept / len(centres)
    return shares


def after_redraws(
    dist: Mapping[str, float], fresh: Mapping[str, float], shares: Mapping[str, float]
) -> dict[str, float]:
    """``dist`` after the generator's visibility redraws (see the module doc): a draw at s is kept
    with ``shares[s]``, a refused one is drawn again from ``fresh`` until kept."""
    kept = {sid: p * shares.get(sid, 1.0) for sid, p in dist.items()}
    refused = sum(dist.values()) - sum(kept.values())
    fresh_kept = {sid: p * shares.get(sid, 1.0) for sid, p in fresh.items()}
    total = sum(fresh_kept.values())
    if refused > 0 and total > 0:
        for sid, p in fresh_kept.items():
            kept[sid] = kept.get(sid, 0.0) + refused * p / total
    return {sid: p for sid, p in sorted(kept.items()) if p > 0}


def chain(
    start: Mapping[str, float], fresh: Mapping[str, float], move: float, steps: int
) -> dict[str, float]:
    """``start`` after ``steps`` scenes of the stats schedules' chain: stay with 1 − ``move``,
    else a draw from ``fresh`` among the other places (see the module doc)."""
    places = sorted(set(start) | set(fresh))
    x = {p: start.get(p, 0.0) for p in places}
    q = {p: fresh.get(p, 0.0) for p in places}
    for _ in range(steps):
        leave = {p: x[p] / (1.0 - q[p]) if q[p] < 1.0 else 0.0 for p in places}
        out = sum(leave.values())
        x = {
            p: (1.0 - move) * x[p]
            + move * (q[p] * (out - leave[p]) + (x[p] if q[p] >= 1.0 else 0.0))
            for p in places
        }
    return {p: v for p, v in x.items() if v > 0}


def schedule_distribution(
    home_name: str, schedule: str | None, *, scene: int | None = None
) -> dict[str, dict[str, float]]:
    """class → static id → P(there in ``scene``) under the schedule's generator, after its
    visibility redraws (for stats schedules: the first scene's)."""
    home = load_home(home_name)
    seeded = parse_seeded(schedule) if schedule else None
    if seeded is not None and seeded[0] in ROUTINE_KINDS:
        return time_blind_distribution(home, seeded[0], seeded[1], scene_day(scene or 1) // 7)
    stats = PlacementStats.load()
    statics = sorted_statics(home)
    if seeded is not None and seeded[0] == "moved" and scene is not None and scene >= MOVE_SCENE:
        drawn = habit_distribution(home, seeded[1], moved_habits(home, seeded[1]))
    elif seeded is not None and seeded[0] in ("habit", "moved"):
        drawn = habit_distribution(home, seeded[1])
    else:
        drawn = {cls: stats_distribution(w, statics) for cls, w in sorted(stats.counts.items())}
    return redrawn(home, drawn)


def redrawn(home: Home, drawn: Mapping[str, Mapping[str, float]]) -> dict[str, dict[str, float]]:
    """class → static id → P: each class's ``drawn`` distribution after the visibility redraws
    of ``home`` (:func:`after_redraws`; the fresh draw is the class's placement statistics)."""
    stats = PlacementStats.load()
    statics = sorted_statics(home)
    return {
        cls: after_redraws(
            d, stats_distribution(stats.counts[cls], statics), seeable_shares(home, cls)
        )
        for cls, d in sorted(drawn.items())
    }


#: Scenes per (slot, day type, week) that :func:`time_of_day_distribution` draws: its error is
#: at most 0.016 sd a place.
REFERENCE_SCENES = 1000
#: Keyed by (resolved data folder, home name, kind, seed, week, weekend, slot).
_LANDED: dict[tuple[Path, str, str, int, int, bool, int], dict[str, dict[str, float]]] = {}


def time_of_day_distribution(
    home: Home, kind: str, seed: int, week: int, weekend: bool, slot: int
) -> dict[str, dict[str, float]]:
    """A routine kind's (``routine`` or ``homer``) per-scene distribution of one slot and day
    type in ``week`` (0-based), *as the scenes land*: the share of ``REFERENCE_SCENES`` scenes,
    drawn by the generator's own scene rule (``routine_scene``, ``homer_scene``) from a seed of
    their own, in which each class lands on each static (the module doc says why not the closed
    form). HOMER's days are all alike: ``week`` and ``weekend`` are ignored."""
    if kind == "homer":
        week, weekend = 0, False
    key = (data_key(), home.name, kind, seed, week, weekend, slot)
    if key not in _LANDED:
        rng = random.Random(f"{kind}-reference:{home.name}:{seed}:{week}:{weekend}:{slot}")
        if kind == "homer":
            table = homer_table(home, seed)
            scene = partial(homer_scene, rng, home, table, slot)
            closed = redrawn(home, homer_slot_distribution(home, seed, slot))
        else:
            routines = routines_by_week(home, seed, week + 1)[week]
            scene = partial(routine_scene, rng, home, routines, weekend, slot)
            closed = redrawn(home, routine_distribution(home, routines, weekend, slot))
        # The closed form (visibility redraws only) counts as one scene, a prior: a place the
        # drawn scenes missed keeps a small share rather than none.
        counts = {cls: dict(d) for cls, d in closed.items()}
        for _ in range(REFERENCE_SCENES):
            placed, _refused = scene()
            for p in placed.values():
                if p.support is not None:
                    per = counts.setdefault(p.cls, {})
                    per[p.support] = per.get(p.support, 0.0) + 1.0
        _LANDED[key] = {
            cls: {sid: n / sum(per.values()) for sid, n in sorted(per.items())}
            for cls, per in sorted(counts.items())
        }
    return {cls: dict(d) for cls, d in _LANDED[key].items()}


def time_blind_distribution(
    home: Home, kind: str, seed: int, week: int
) -> dict[str, dict[str, float]]:
    """The average of :func:`time_of_day_distribution` over a week's scenes (HOMER: over a day's,
    every day alike): where a class is at a moment of the week drawn at random."""
    days = ((False, 1.0),) if kind == "homer" else ((False, 5 / 7), (True, 2 / 7))
    out: dict[str, dict[str, float]] = {}
    for weekend, share in days:
        for slot in range(SCENES_PER_DAY):
            for cls, dist in time_of_day_distribution(
                home, kind, seed, week, weekend, slot
            ).items():
                per = out.setdefault(cls, {})
                for sid, p in dist.items():
                    per[sid] = per.get(sid, 0.0) + share * p / SCENES_PER_DAY
    return {cls: dict(sorted(d.items())) for cls, d in sorted(out.items())}


@dataclass
class DistributionOracle:
    last_seq: int = 0
    tasks_folded: int = 0
    home: str | None = None
    schedule: str | None = None
    dist: dict[str, dict[str, float]] = field(default_factory=dict)
    by_class: dict[Pair, float] = field(default_factory=dict)
    #: ``moved-<seed>``: the distribution from the move on.
    moved: dict[str, dict[str, float]] | None = None
    #: ``routine-<seed>``: the time-blind distribution of each week (the routines drift), by
    #: week, computed when first asked.
    weekly: dict[int, dict[str, dict[str, float]]] | None = None
    #: ``stats-<seed>``: the move rate of its Markov chain, and where each class was last seen
    #: (place, scene).
    move_rate: float | None = None
    last_seen: dict[str, tuple[str, int]] = field(default_factory=dict)
    today: Today = field(default_factory=Today)
    _cache: dict[str, dict[str, float]] = field(default_factory=dict, repr=False, compare=False)

    def apply(self, event: EventView) -> None:
        self._cache = {}
        if event.type == "run_started" and self.home is None:
            run = decode(event, RunStarted)
            self._load(run.home, run.schedule)
        elif event.type == "scene_graph_seeded":
            seeded = decode(event, SceneGraphSeeded)
            self.today.classes = tuple(sorted({v.dynamic for v in seeded.values}))
        elif event.type == "task_started":
            started = decode(event, TaskStarted)
            if self.today.starts(event, started):
                key = self.today.key
                if key is not None and key[0] == "scene":
                    for d, place in self.today.seen.items():
                        self.last_seen[d] = (place, key[1])
                self.today.open(event, started)
        self.today.apply(event)
        if event.type == "task_ended":
            self.tasks_folded += 1
        self.last_seq = event.seq

    def _load(self, home: str, schedule: str | None) -> None:
        self.home, self.schedule = home, schedule
        self.dist = schedule_distribution(home, schedule)
        seeded = parse_seeded(schedule) if schedule else None
        if seeded is not None and seeded[0] == "moved":
            self.moved = schedule_distribution(home, schedule, scene=MOVE_SCENE)
        if seeded is not None and seeded[0] in ROUTINE_KINDS:
            self.weekly = {}
        if seeded is not None and seeded[0] == "stats":
            self.move_rate = PlacementStats.load().move_rate
        statics = load_home(home).statics
        self.by_class = {}
        for cls, per in self.dist.items():
            for sid, p in per.items():
                pair = (cls, statics[sid].cls)
                self.by_class[pair] = min(1.0, self.by_class.get(pair, 0.0) + p)

    def instance_rel(self, dynamic: str, static_id: str, static_class: str) -> float:
        now = self._cache.get(dynamic)
        if now is None:
            key = self.today.key
            base = self._scene_dist(key).get(dynamic, {})
            last = self.last_seen.get(dynamic)
            if self.move_rate is not None and key is not None and key[0] == "scene":
                if last is None:
                    base = chain(base, base, self.move_rate, max(key[1] - 1, 0))
                else:
                    steps = max(key[1] - last[1], 0)
                    base = chain({last[0]: 1.0}, base, self.move_rate, steps)
            now = self._cache[dynamic] = self.today.condition(dynamic, base)
        return now.get(static_id, 0.0)

    def _scene_dist(self, key: tuple[str, int] | None) -> Mapping[str, Mapping[str, float]]:
        """The per-scene distribution of the episode ``key`` (before today's evidence)."""
        if key is None or key[0] != "scene":
            return self.dist
        if self.moved is not None and key[1] >= MOVE_SCENE:
            return self.moved
        if self.weekly is not None:
            return self._week(scene_day(key[1]) // 7)
        return self.dist

    def _week(self, week: int) -> dict[str, dict[str, float]]:
        assert self.weekly is not None and self.home is not None
        if week not in self.weekly:
            first = 7 * SCENES_PER_DAY * week + 1
            self.weekly[week] = schedule_distribution(self.home, self.schedule, scene=first)
        return self.weekly[week]

    def rel(self, dynamic: str, static: str) -> float:
        return self.by_class.get((dynamic, static), 0.0)

    @property
    def state(self) -> Mapping[Pair, float]:
        return MappingProxyType(dict(sorted(self.by_class.items())))

    def as_table(self) -> dict[str, dict[str, float]]:
        table: dict[str, dict[str, float]] = {}
        for (d, s), v in sorted(self.by_class.items()):
            table.setdefault(d, {})[s] = v
        return table

    snapshot_name: ClassVar[str] = "distribution_oracle"
    snapshot_version: ClassVar[int] = 2  # 2: today's evidence

    def to_snapshot(self) -> dict[str, Any]:
        return {
            "home": self.home,
            "schedule": self.schedule,
            "tasks_folded": self.tasks_folded,
            "today": self.today.to_snapshot(),
            "last_seen": {d: list(v) for d, v in sorted(self.last_seen.items())},
        }

    @classmethod
    def from_snapshot(cls, state: Mapping[str, Any], last_seq: int) -> DistributionOracle:
        oracle = cls(
            last_seq=last_seq,
            tasks_folded=int(state["tasks_folded"]),
            today=Today.from_snapshot(state["today"]),
            last_seen={d: (str(v[0]), int(v[1])) for d, v in state["last_seen"].items()},
        )
        if state["home"] is not None:
            oracle._load(state["home"], state["schedule"])
        return oracle


@dataclass
class SlotOracle(DistributionOracle):
    """The distribution oracle that also knows the time of day: on ``routine-<seed>`` the
    routine's exact per-scene distribution for the scene's slot and day type
    and, on ``homer-<seed>``, the slot's, as the scenes land (:func:`time_of_day_distribution`,
    the week's routines); elsewhere the same as
    :class:`DistributionOracle`. A REFERENCE (the ceiling of a memory that knows the hour)."""

    slots: dict[tuple[int, bool, int], dict[str, dict[str, float]]] = field(default_factory=dict)

    def _scene_dist(self, key: tuple[str, int] | None) -> Mapping[str, Mapping[str, float]]:
        if self.weekly is None or key is None or key[0] != "scene" or self.home is None:
            return super()._scene_dist(key)
        seeded = parse_seeded(self.schedule) if self.schedule else None
        assert seeded is not None
        day = scene_day(key[1])
        which = (day // 7, day % 7 in WEEKEND, (key[1] - 1) % SCENES_PER_DAY)
        if which not in self.slots:
            self.slots[which] = time_of_day_distribution(
                load_home(self.home), seeded[0], seeded[1], *which
            )
        return self.slots[which]

    snapshot_name: ClassVar[str] = "slot_oracle"

    @classmethod
    def from_snapshot(cls, state: Mapping[str, Any], last_seq: int) -> SlotOracle:
        oracle = super().from_snapshot(state, last_seq)
        assert isinstance(oracle, SlotOracle)
        return oracle
