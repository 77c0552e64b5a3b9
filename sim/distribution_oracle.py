"""A REFERENCE searcher's knowledge, never a robot's: the distribution a schedule draws from.

:class:`DistributionOracle` is a relation model (``RelationSpec("dist-oracle")``) that, on
``run_started``, reads the run's home and schedule and values each static instance by the
probability that the schedule's generator puts the target there in a scene — nothing of today's
draw. It is the best any memory of the schedule could learn, so a strategy's first search of the
day can be read as regret against it. It folds no evidence.

- ``habit-<seed>``: the exact per-scene distribution (:func:`habit_distribution`);
- ``stats-<seed>`` / ``rearr-<seed>``'s stats fallback: the first scene's draw
  (:func:`stats_distribution`); later scenes keep the object with probability 1 − move rate, and
  the marginal of a Markov chain started there stays close to it but not equal (an approximation).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar, Final

from objsearch.agent.catalogue import RunStarted, decode
from objsearch.agent.home import load_home
from objsearch.agent.scene_graph import EventLike, Pair
from objsearch.agent.strategies import RelationModels
from objsearch.sim.habit_schedule import habit_distribution, stats_distribution
from objsearch.sim.schedule_names import parse_seeded
from objsearch.sim.stats_schedule import PlacementStats


def schedule_distribution(home_name: str, schedule: str | None) -> dict[str, dict[str, float]]:
    """class → static id → P(there in a scene) under the schedule's generator."""
    home = load_home(home_name)
    seeded = parse_seeded(schedule) if schedule else None
    if seeded is not None and seeded[0] == "habit":
        return habit_distribution(home, seeded[1])
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

    def apply(self, event: EventLike) -> None:
        if event.type == "run_started" and self.home is None:
            run = decode(event, RunStarted)
            self._load(run.home, run.schedule)
        elif event.type == "task_ended":
            self.tasks_folded += 1
        self.last_seq = event.seq

    def _load(self, home: str, schedule: str | None) -> None:
        self.home, self.schedule = home, schedule
        self.dist = schedule_distribution(home, schedule)
        statics = load_home(home).statics
        self.by_class = {}
        for cls, per in self.dist.items():
            for sid, p in per.items():
                pair = (cls, statics[sid].cls)
                self.by_class[pair] = min(1.0, self.by_class.get(pair, 0.0) + p)

    def instance_rel(self, dynamic: str, static_id: str, static_class: str) -> float:
        return self.dist.get(dynamic, {}).get(static_id, 0.0)

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
    snapshot_version: ClassVar[int] = 1

    def to_snapshot(self) -> dict[str, Any]:
        return {"home": self.home, "schedule": self.schedule, "tasks_folded": self.tasks_folded}

    @classmethod
    def from_snapshot(cls, state: Mapping[str, Any], last_seq: int) -> DistributionOracle:
        oracle = cls(last_seq=last_seq, tasks_folded=int(state["tasks_folded"]))
        if state["home"] is not None:
            oracle._load(state["home"], state["schedule"])
        return oracle


#: The simulator's relation models by name, for a fold of a log whose spec may name one
#: (``AgentState(models=SIM_MODELS)``, ``Session.open(..., models=SIM_MODELS)``).
SIM_MODELS: Final[RelationModels] = MappingProxyType({"dist-oracle": DistributionOracle})
