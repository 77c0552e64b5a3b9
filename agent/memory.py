"""Memory of where things are: a belief per (target, static *instance*), folded from the log.

Per (object class d, static instance s) it keeps

- ``seen``: long-run count of tasks in which d was seen at s (a ``detection`` with its support
  ``at`` s) — the frequency of a place;
- ``missed``: long-run count of tasks that looked at s (``view_taken``) for target d and did not
  find it there — negative evidence;
- ``recent_seen`` / ``recent_missed``: the same counts fading with a half-life of h tasks —
  recency: an object does not move during a scene, so what the last searches saw counts most;

and values s for d as the posterior mean of a Beta whose prior is the class-level belief
(:class:`~objsearch.agent.relations.BetaRelations` over the same log, seeded from Visual Genome;
statics never seen or looked at keep exactly that value):

    a = k·p₀ + seen + W·recent_seen,   b = k·(1 − p₀) + missed + W·recent_missed,   value = a/(a+b)

k (prior strength), h and W are recorded in the run spec (``RelationSpec("memory", k, h, W)``).
:meth:`rel` (per class) is the class-level belief, so anything that asks per class still works.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

from objsearch.agent.catalogue import (
    Detected,
    PlanComputed,
    RunStarted,
    TaskStarted,
    ViewTaken,
    decode,
)
from objsearch.agent.relations import BetaRelations
from objsearch.agent.scene_graph import Pair, UpdateMode
from objsearch.agent.sightings import LastSeen, Sighting, sighting, sighting_row
from objsearch.agent.task_experience import SeenBy, TaskExperience
from objsearch.events.projection import EventView

Key = tuple[str, str]  # (object class, static id)


@dataclass
class InstanceMemory:
    prior_strength: float = 2.0
    half_life_tasks: float = 8.0
    recent_weight: float = 10.0
    classes: BetaRelations = field(default_factory=BetaRelations)
    last_seq: int = 0
    tasks_folded: int = 0
    seen: dict[Key, float] = field(default_factory=dict)
    missed: dict[Key, float] = field(default_factory=dict)
    recent_seen: dict[Key, float] = field(default_factory=dict)
    recent_missed: dict[Key, float] = field(default_factory=dict)
    static_class: dict[str, str] = field(default_factory=dict)
    sightings: LastSeen = field(default_factory=LastSeen)
    update_mode: UpdateMode = UpdateMode.ALL
    #: the task in progress, by static *instance* (``viewed``: the static ids looked at)
    _task: TaskExperience = field(default_factory=lambda: TaskExperience(SeenBy.INSTANCE))

    def __post_init__(self) -> None:
        if self.prior_strength <= 0 or self.half_life_tasks <= 0 or self.recent_weight < 0:
            raise ValueError("memory needs prior strength > 0, half-life > 0, recent weight >= 0")
        self.classes.prior_strength = self.prior_strength

    @property
    def last_seen(self) -> Mapping[str, Sighting]:
        return self.sightings.last

    def apply(self, event: EventView) -> None:
        self.classes.apply(event)
        self.sightings.apply(event)
        kind = event.type
        if kind == "run_started":
            self.update_mode = UpdateMode(decode(event, RunStarted).update_mode)
        elif kind == "task_started":
            self._task.start(decode(event, TaskStarted).target)
            factor = 0.5 ** (1.0 / self.half_life_tasks)
            self.recent_seen = {k: v * factor for k, v in self.recent_seen.items() if v > 1e-6}
            self.recent_missed = {k: v * factor for k, v in self.recent_missed.items() if v > 1e-6}
        elif kind == "plan_computed":
            for c in decode(event, PlanComputed).candidates:
                self.static_class[c.static_id] = c.static_class
        elif kind == "view_taken":
            static_id = decode(event, ViewTaken).static_id
            if static_id is not None:
                self._task.viewed.add(static_id)
        elif kind == "detection":
            detected = decode(event, Detected)
            support = detected.support
            if detected.accepted and support is not None and support.at:
                self.static_class[support.static_id] = support.static_class
            self._task.detected(detected)
        elif kind == "task_ended":
            self._end_task()
        elif kind == "task_aborted":
            self._task.clear()
        self.last_seq = event.seq

    def _end_task(self) -> None:
        task = self._task
        if self.update_mode is UpdateMode.ALL:
            chosen = dict(task.seen_at)
        elif self.update_mode is UpdateMode.TARGETS and task.target in task.seen_at:
            chosen = {task.target: task.seen_at[task.target]}
        else:
            chosen = {}
        for d, statics in chosen.items():
            for sid in statics:
                self.seen[(d, sid)] = self.seen.get((d, sid), 0.0) + 1.0
                self.recent_seen[(d, sid)] = self.recent_seen.get((d, sid), 0.0) + 1.0
        target = task.target
        if self.update_mode is not UpdateMode.NONE and target is not None:
            for sid in task.missed():
                self.missed[(target, sid)] = self.missed.get((target, sid), 0.0) + 1.0
                self.recent_missed[(target, sid)] = self.recent_missed.get((target, sid), 0.0) + 1.0
        task.clear()
        self.tasks_folded += 1

    # -- values -------------------------------------------------------------------------------

    def instance_rel(self, dynamic: str, static_id: str, static_class: str) -> float:
        p0 = self.classes.rel(dynamic, static_class)
        key = (dynamic, static_id)
        if p0 <= 0 and key not in self.seen:
            return 0.0  # never plausible, never seen: not a candidate
        k, w = self.prior_strength, self.recent_weight
        a = k * p0 + self.seen.get(key, 0.0) + w * self.recent_seen.get(key, 0.0)
        b = k * (1 - p0) + self.missed.get(key, 0.0) + w * self.recent_missed.get(key, 0.0)
        return a / (a + b)

    def rel(self, dynamic: str, static: str) -> float:
        return self.classes.rel(dynamic, static)

    @property
    def state(self) -> Mapping[Pair, float]:
        return self.classes.state

    def as_table(self) -> dict[str, dict[str, float]]:
        return self.classes.as_table()

    def instances(self, dynamic: str) -> dict[str, float]:
        """Every static instance the log knows, with its value for ``dynamic``."""
        return {
            sid: self.instance_rel(dynamic, sid, cls)
            for sid, cls in sorted(self.static_class.items())
        }

    # -- snapshots ------------------------------------------------------------------------------

    snapshot_name: ClassVar[str] = "instance_memory"
    snapshot_version: ClassVar[int] = 2  # 2: sightings away from mapped places, with position

    def to_snapshot(self) -> dict[str, Any]:
        def rows(d: Mapping[Key, float]) -> list[list[Any]]:
            return [[a, b, v] for (a, b), v in sorted(d.items())]

        return {
            "prior_strength": self.prior_strength,
            "half_life_tasks": self.half_life_tasks,
            "recent_weight": self.recent_weight,
            "classes": self.classes.to_snapshot(),
            "tasks_folded": self.tasks_folded,
            "seen": rows(self.seen),
            "missed": rows(self.missed),
            "recent_seen": rows(self.recent_seen),
            "recent_missed": rows(self.recent_missed),
            "static_class": dict(sorted(self.static_class.items())),
            "last_seen": {d: list(sighting_row(s)) for d, s in sorted(self.last_seen.items())},
            "update_mode": self.update_mode.value,
            "task": [self._task.target, self.sightings.task_id, self.sightings.scene],
            "seen_at": self._task.seen_at_rows(),
            "viewed": sorted(self._task.viewed),
            "sightings": {
                d: list(sighting_row(s)) for d, s in sorted(self.sightings.pending.items())
            },
        }

    @classmethod
    def from_snapshot(cls, state: Mapping[str, Any], last_seq: int) -> InstanceMemory:
        def rows(r: list[list[Any]]) -> dict[Key, float]:
            return {(a, b): float(v) for a, b, v in r}

        target, task_id, scene = state["task"]
        return cls(
            prior_strength=float(state["prior_strength"]),
            half_life_tasks=float(state["half_life_tasks"]),
            recent_weight=float(state["recent_weight"]),
            classes=BetaRelations.from_snapshot(state["classes"], last_seq),
            last_seq=last_seq,
            tasks_folded=int(state["tasks_folded"]),
            seen=rows(state["seen"]),
            missed=rows(state["missed"]),
            recent_seen=rows(state["recent_seen"]),
            recent_missed=rows(state["recent_missed"]),
            static_class=dict(state["static_class"]),
            sightings=LastSeen(
                last={d: sighting(r) for d, r in state["last_seen"].items()},
                task_id=task_id,
                scene=scene,
                pending={d: sighting(r) for d, r in state["sightings"].items()},
            ),
            update_mode=UpdateMode(state["update_mode"]),
            _task=TaskExperience(
                SeenBy.INSTANCE,
                target=target,
                seen_at=TaskExperience.seen_at_from(state["seen_at"]),
                viewed=set(state["viewed"]),
            ),
        )
