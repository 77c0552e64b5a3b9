"""Relation models: folds of the event log into Rel(o_d, o_s), the seam new learning rules plug into.

The paper's rule is Eq. 4 (:class:`objsearch.agent.scene_graph.SceneGraphProjection`). Here is a
second one, folding the *same* events (schema v1, no new fields):

:class:`BetaRelations` keeps a Beta(a, b) posterior per (semi-dynamic, static) class pair, seeded
from the Visual Genome prior as a = k·Rel₀, b = k·(1 − Rel₀) (k pseudo-observations). At the end of a
task it adds

- **positive evidence** a += 1 for every pair Eq. 4 would raise (the class was seen at the static
  class; which classes count follows the update mode, as in Eq. 4);
- **negative evidence** b += 1 for (target, s) for every static class s the robot looked at or
  opened during the task without seeing the target there — something Eq. 4 never does;

and, with a half-life h (in tasks), multiplies all evidence by 2^(−1/h) when a task starts, so old
sightings fade back toward the prior. Rel is the posterior mean a / (a + b).

Which static class a ``view_taken`` looked at comes from the ``plan_computed`` candidates of the same
task (the plan lists each static id with its class), so the fold needs nothing but the log.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar, Protocol

from objsearch.agent.catalogue import (
    Detected,
    PlanComputed,
    RunStarted,
    SceneGraphSeeded,
    TaskStarted,
    ViewTaken,
    decode,
)
from objsearch.agent.scene_graph import Pair, UpdateMode, experience_to_fold
from objsearch.agent.task_experience import TaskExperience
from objsearch.events.projection import EventView, Projection


class RelationModel(Projection[Mapping[Pair, float]], Protocol):
    """What the search policy needs from a scene graph: a projection (a fold of the log) whose
    state is Rel per class pair."""

    tasks_folded: int
    last_seq: int

    def apply(self, event: EventView) -> None: ...

    def rel(self, dynamic: str, static: str) -> float: ...

    @property
    def state(self) -> Mapping[Pair, float]: ...

    def as_table(self) -> dict[str, dict[str, float]]: ...


@dataclass
class BetaRelations:
    """Beta posterior per pair with negative evidence and optional decay (see the module doc)."""

    prior_strength: float = 2.0
    half_life_tasks: float | None = None
    update_mode: UpdateMode = UpdateMode.ALL
    last_seq: int = 0
    tasks_folded: int = 0
    prior: dict[Pair, float] = field(default_factory=dict)
    positive: dict[Pair, float] = field(default_factory=dict)
    negative: dict[Pair, float] = field(default_factory=dict)
    _static_class: dict[str, str] = field(default_factory=dict)
    #: the task in progress; ``viewed`` holds the static *classes* looked at
    _task: TaskExperience = field(default_factory=TaskExperience)

    def __post_init__(self) -> None:
        if self.prior_strength <= 0:
            raise ValueError(f"prior strength must be positive, got {self.prior_strength}")
        if self.half_life_tasks is not None and self.half_life_tasks <= 0:
            raise ValueError(f"half-life must be positive, got {self.half_life_tasks}")

    @property
    def decay(self) -> float:
        """Factor applied to all evidence when a task starts (1 without decay)."""
        return 1.0 if self.half_life_tasks is None else 0.5 ** (1.0 / self.half_life_tasks)

    def apply(self, event: EventView) -> None:
        kind = event.type
        if kind == "run_started":
            self.update_mode = UpdateMode(decode(event, RunStarted).update_mode)
        elif kind == "scene_graph_seeded":
            self.prior = {
                (v.dynamic, v.static): v.rel for v in decode(event, SceneGraphSeeded).values
            }
            self.positive = {}
            self.negative = {}
        elif kind == "task_started":
            self._task.start(decode(event, TaskStarted).target)
            self._static_class = {}
            self._fade()
        elif kind == "plan_computed":
            for c in decode(event, PlanComputed).candidates:
                self._static_class[c.static_id] = c.static_class
        elif kind == "view_taken":
            static_id = decode(event, ViewTaken).static_id
            cls = None if static_id is None else self._static_class.get(static_id)
            if cls is not None:
                self._task.viewed.add(cls)
        elif kind == "detection":
            self._task.detected(decode(event, Detected))
        elif kind == "task_ended":
            self._end_task()
        elif kind == "task_aborted":  # a search cut short by a crash folds nothing
            self._task.clear()
        self.last_seq = event.seq

    def _fade(self) -> None:
        factor = self.decay
        if factor == 1.0:
            return
        self.positive = {p: v * factor for p, v in self.positive.items()}
        self.negative = {p: v * factor for p, v in self.negative.items()}

    def _end_task(self) -> None:
        task = self._task
        known = {d for d, _ in self.prior}
        chosen = experience_to_fold(self.update_mode, task.target, task.seen_at, known)
        for d, statics in chosen.items():
            for s in statics:
                if (d, s) in self.prior:
                    self.positive[(d, s)] = self.positive.get((d, s), 0.0) + 1.0
        target = task.target
        if self.update_mode is not UpdateMode.NONE and target in known:
            for s in task.missed():
                if (target, s) in self.prior:
                    self.negative[(target, s)] = self.negative.get((target, s), 0.0) + 1.0
        task.clear()
        self.tasks_folded += 1

    snapshot_name: ClassVar[str] = "beta_relations"
    snapshot_version: ClassVar[int] = 1

    def to_snapshot(self) -> dict[str, Any]:
        def pairs(d: Mapping[Pair, float]) -> list[list[Any]]:
            return [[a, b, v] for (a, b), v in sorted(d.items())]

        return {
            "prior_strength": self.prior_strength,
            "half_life_tasks": self.half_life_tasks,
            "update_mode": self.update_mode.value,
            "tasks_folded": self.tasks_folded,
            "prior": pairs(self.prior),
            "positive": pairs(self.positive),
            "negative": pairs(self.negative),
            "static_class": dict(sorted(self._static_class.items())),
            "target": self._task.target,
            "seen_at": self._task.seen_at_rows(),
            "viewed": sorted(self._task.viewed),
        }

    @classmethod
    def from_snapshot(cls, state: Mapping[str, Any], last_seq: int) -> BetaRelations:
        def pairs(rows: list[list[Any]]) -> dict[Pair, float]:
            return {(a, b): float(v) for a, b, v in rows}

        return cls(
            prior_strength=float(state["prior_strength"]),
            half_life_tasks=state["half_life_tasks"],
            update_mode=UpdateMode(state["update_mode"]),
            last_seq=last_seq,
            tasks_folded=int(state["tasks_folded"]),
            prior=pairs(state["prior"]),
            positive=pairs(state["positive"]),
            negative=pairs(state["negative"]),
            _static_class=dict(state["static_class"]),
            _task=TaskExperience(
                target=state["target"],
                seen_at=TaskExperience.seen_at_from(state["seen_at"]),
                viewed=set(state["viewed"]),
            ),
        )

    def rel(self, dynamic: str, static: str) -> float:
        pair = (dynamic, static)
        if pair not in self.prior:
            return 0.0
        k = self.prior_strength
        a = k * self.prior[pair] + self.positive.get(pair, 0.0)
        b = k * (1.0 - self.prior[pair]) + self.negative.get(pair, 0.0)
        return a / (a + b)

    @property
    def relations(self) -> dict[Pair, float]:
        return {pair: self.rel(*pair) for pair in sorted(self.prior)}

    @property
    def state(self) -> Mapping[Pair, float]:
        return MappingProxyType(self.relations)

    def as_table(self) -> dict[str, dict[str, float]]:
        table: dict[str, dict[str, float]] = {}
        for (d, s), value in self.relations.items():
            table.setdefault(d, {})[s] = value
        return table


class InstanceRelations(Protocol):
    """A relation model that also values each static *instance* (the memory, the distribution
    oracle): the planner then weighs a stop by its instances, not by their class."""

    def instance_rel(self, dynamic: str, static_id: str, static_class: str) -> float: ...


def per_instance(model: object) -> bool:
    return callable(getattr(model, "instance_rel", None))


def instance_value(model: RelationModel, dynamic: str, static_id: str, static_class: str) -> float:
    """The instance's value under ``model``: its own for an instance model, else its class's Rel."""
    if per_instance(model):
        own: InstanceRelations = model  # type: ignore[assignment]
        return own.instance_rel(dynamic, static_id, static_class)
    return model.rel(dynamic, static_class)
