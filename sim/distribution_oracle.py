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
  averaged over the week's slots and days (:func:`blind_distribution`) for the routines in force
  that week (it knows the days of the drift, not the hour): the best a memory that ignores the
  time of day could learn;
- ``stats-<seed>`` / ``rearr-<seed>``'s stats fallback: the first scene's draw
  (:func:`stats_distribution`); later scenes keep the object with probability 1 − move rate, so
  once the robot has seen the object in scene n₀, scene n's distribution is the chain's
  (1 − m)^(n−n₀)·δ(where it was seen) + (1 − (1 − m)^(n−n₀))·draw (an approximation: a move
  excludes the old place, and visibility redraws are left out). Without this the "reference"
  lost to a memory that simply remembers yesterday.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar, Final

from objsearch.agent.belief import Today
from objsearch.agent.catalogue import RunStarted, SceneGraphSeeded, TaskStarted, decode
from objsearch.agent.home import load_home
from objsearch.agent.scene_graph import EventLike, Pair
from objsearch.agent.strategies import RelationModels
from objsearch.sim.habit_schedule import (
    MOVE_SCENE,
    habit_distribution,
    moved_habits,
    stats_distribution,
)
from objsearch.sim.routine_schedule import (
    SCENES_PER_DAY,
    WEEKEND,
    blind_distribution,
    routine_distribution,
    routines_by_week,
    scene_day,
)
from objsearch.sim.schedule_names import parse_seeded
from objsearch.sim.stats_schedule import PlacementStats


def schedule_distribution(
    home_name: str, schedule: str | None, *, scene: int | None = None
) -> dict[str, dict[str, float]]:
    """class → static id → P(there in ``scene``) under the schedule's generator."""
    home = load_home(home_name)
    seeded = parse_seeded(schedule) if schedule else None
    if seeded is not None and seeded[0] == "moved" and scene is not None and scene >= MOVE_SCENE:
        return habit_distribution(home, seeded[1], moved_habits(home, seeded[1]))
    if seeded is not None and seeded[0] in ("habit", "moved"):
        return habit_distribution(home, seeded[1])
    if seeded is not None and seeded[0] == "routine":
        week = scene_day(scene or 1) // 7
        return blind_distribution(home, routines_by_week(home, seeded[1], week + 1)[week])
    stats = PlacementStats.load()
    statics = sorted(home.statics.values(), key=lambda s: s.id)
    return {cls: stats_distribution(w, statics) for cls, w in sorted(stats.counts.items())}


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

    def apply(self, event: EventLike) -> None:
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
        if seeded is not None and seeded[0] == "routine":
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
            if self.move_rate is not None and last is not None and key is not None:
                stay = (1 - self.move_rate) ** max(key[1] - last[1], 0)
                base = {p: (1 - stay) * v for p, v in base.items()}
                base[last[0]] = base.get(last[0], 0.0) + stay
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
    (:func:`routine_distribution`, the week's routines); elsewhere the same as
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
            home = load_home(self.home)
            table = routines_by_week(home, seeded[1], which[0] + 1)[which[0]]
            self.slots[which] = routine_distribution(home, table, which[1], which[2])
        return self.slots[which]

    snapshot_name: ClassVar[str] = "slot_oracle"

    @classmethod
    def from_snapshot(cls, state: Mapping[str, Any], last_seq: int) -> SlotOracle:
        oracle = super().from_snapshot(state, last_seq)
        assert isinstance(oracle, SlotOracle)
        return oracle


#: The simulator's relation models by name, for a fold of a log whose spec may name one
#: (``AgentState(models=SIM_MODELS)``, ``Session.open(..., models=SIM_MODELS)``).
SIM_MODELS: Final[RelationModels] = MappingProxyType(
    {"dist-oracle": DistributionOracle, "slot-oracle": SlotOracle}
)
