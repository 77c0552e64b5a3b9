"""The scene graph: Rel(o_d, o_s) in [0, 1], seeded by Eq. 2 and updated by Eq. 4.

The graph is a projection of the event log. The agent never stores it: it folds ``scene_graph_seeded``
(the prior values), ``run_started`` (the update mode), ``task_started``, accepted ``detection`` events
(the experience pool) and ``task_ended`` (the moment Eq. 4 applies). Folding a whole log from scratch
and folding it event by event as it is written give identical values, because they are the same
operations in the same order.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Container, Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar

from objsearch.agent.catalogue import Detected, RunStarted, SceneGraphSeeded, TaskStarted, decode
from objsearch.agent.categories import Category, Vocabulary
from objsearch.agent.maps import MapEvidence
from objsearch.agent.task_experience import TaskExperience
from objsearch.events.projection import EventView

Pair = tuple[str, str]  # (semi-dynamic class, static class)


class UpdateMode(enum.Enum):
    """Which experience Eq. 4 folds in at the end of a task (paper §6.1.2)."""

    NONE = "none"  # never update: the prior stays
    TARGETS = "targets"  # only pairs of the task's target
    ALL = "all"  # every semi-dynamic object seen during the task


def experience_to_fold(
    mode: UpdateMode,
    target: str | None,
    seen_at: Mapping[str, set[str]],
    known: Container[str],
) -> dict[str, set[str]]:
    """The part of a task's experience (each semi-dynamic class seen → the static classes it was
    seen at) that the update folds in under ``mode``: every ``known`` class, only the target, or
    nothing. The one Python statement of the choice; ``eq4_updates`` in :mod:`.scene_graph_sql`
    restates it for the lake."""
    if mode is UpdateMode.ALL:
        return {d: s for d, s in seen_at.items() if d in known}
    if mode is UpdateMode.TARGETS and target is not None and target in seen_at:
        return {target: seen_at[target]}
    return {}


def seed_relations(prior: Mapping[str, Any], vocabulary: Vocabulary) -> dict[Pair, float]:
    """Eq. 2: Rel(d, s) = C(d, s) / C(d) for every semi-dynamic d and static s of the vocabulary.

    Alias-merged counts are sums, which can over-count images showing two aliases; the ratio is
    clipped to 1 so Rel stays a value in [0, 1]. A class never seen (C(d) = 0) relates to nothing.
    """
    image_counts = prior["image_counts"]
    pair_counts = prior["pair_counts"]
    relations: dict[Pair, float] = {}
    for d in vocabulary.names(Category.SEMI_DYNAMIC):
        total = float(image_counts.get(d, 0))
        for s in vocabulary.names(Category.STATIC):
            both = float(pair_counts.get(d, {}).get(s, 0))
            relations[(d, s)] = min(1.0, both / total) if total > 0 else 0.0
    return relations


def apply_eq4(
    relations: Mapping[Pair, float], seen_at: Mapping[str, Iterable[str]]
) -> dict[Pair, float]:
    """Eq. 4 for every semi-dynamic class in ``seen_at`` (class → static classes it was seen at).

    Rel/2 + 1/2 where o_d was seen at o_s, Rel/2 where o_d was seen but not at o_s, unchanged for
    classes not seen.
    """
    return _apply_eq4(relations, seen_at, _pairs_by_dynamic(relations))


def _pairs_by_dynamic(relations: Mapping[Pair, float]) -> dict[str, tuple[Pair, ...]]:
    grouped: dict[str, list[Pair]] = {}
    for pair in relations:
        grouped.setdefault(pair[0], []).append(pair)
    return {d: tuple(pairs) for d, pairs in grouped.items()}


def _apply_eq4(
    relations: Mapping[Pair, float],
    seen_at: Mapping[str, Iterable[str]],
    pairs_of: Mapping[str, tuple[Pair, ...]],
) -> dict[Pair, float]:
    # Only the pairs of the classes seen change, so the fold of a long log touches a few pairs per
    # task instead of the whole graph (the 1 M-event rebuild is dominated by task ends).
    updated = dict(relations)
    for d, statics in seen_at.items():
        at = statics if isinstance(statics, (set, frozenset)) else set(statics)
        for pair in pairs_of.get(d, ()):
            updated[pair] = relations[pair] / 2 + (0.5 if pair[1] in at else 0.0)
    return updated


@dataclass
class SceneGraphProjection:
    """Fold of the log into the scene graph (and the experience pool of the task in progress)."""

    relations: dict[Pair, float] = field(default_factory=dict)
    update_mode: UpdateMode = UpdateMode.ALL
    last_seq: int = 0
    tasks_folded: int = 0
    _task: TaskExperience = field(default_factory=TaskExperience)
    _pairs_of: dict[str, tuple[Pair, ...]] = field(default_factory=dict, repr=False)
    #: :meth:`record_handlers`' answer, the id of the projection it was made for (a copy's
    #: handlers would change the original: it makes its own) and the sightings it counts in.
    _handlers: tuple[int, MapEvidence | None, dict[str, Callable[[Any], None]]] | None = field(
        default=None, init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        self._pairs_of = _pairs_by_dynamic(self.relations)

    def apply(self, event: EventView) -> None:
        # Only the types this fold reads are decoded: the rest pass on their ``type`` alone.
        kind = event.type
        if kind == "run_started":
            self._run_started(decode(event, RunStarted))
        elif kind == "scene_graph_seeded":
            self._seeded(decode(event, SceneGraphSeeded))
        elif kind == "task_started":
            self._task.start(decode(event, TaskStarted).target)
        elif kind == "detection":
            # detection v2; older versions are upcast by read_log before they get here.
            self._task.detected(decode(event, Detected))
        elif kind == "task_ended":
            self._end_task()
        elif kind == "task_aborted":
            self._task.clear()  # a search cut short by a crash folds nothing
        self.last_seq = event.seq

    def record_handlers(
        self, sightings: MapEvidence | None = None
    ) -> dict[str, Callable[[Any], None]]:
        """What :meth:`apply` does per type, from a log's records (``events.fold_read``): each
        handler is given the record's envelope with its payload decoded as the type's record
        (made once: they read the projection's fields when called). With ``sightings`` (the
        agent's map evidence), the detection handler also counts each sighting there, in the
        same call (:meth:`MapEvidence.record_handlers`)."""
        made = self._handlers
        if made is not None and made[0] == id(self) and made[1] is sightings:
            return made[2]
        task = self._task
        handlers: dict[str, Callable[[Any], None]] = {
            "run_started": lambda r: self._run_started(r.payload),
            "scene_graph_seeded": lambda r: self._seeded(r.payload),
            "task_started": lambda r: task.start(r.payload.target),
            "detection": task.record_handler()
            if sightings is None
            else sightings.record_handlers(task)["detection"],
            "task_ended": lambda r: self._end_task(),
            "task_aborted": lambda r: task.clear(),
        }
        self._handlers = (id(self), sightings, handlers)
        return handlers

    def folded_to(self, seq: int, time_ns: int) -> None:
        self.last_seq = seq

    def _run_started(self, run: RunStarted) -> None:
        self.update_mode = UpdateMode(run.update_mode)

    def _seeded(self, seeded: SceneGraphSeeded) -> None:
        self.relations = {(v.dynamic, v.static): v.rel for v in seeded.values}
        self._pairs_of = _pairs_by_dynamic(self.relations)

    def _end_task(self) -> None:
        task = self._task
        chosen = experience_to_fold(self.update_mode, task.target, task.seen_at, self._pairs_of)
        if chosen:
            self.relations = _apply_eq4(self.relations, chosen, self._pairs_of)
        task.clear()
        self.tasks_folded += 1

    #: Snapshots (objsearch.events.snapshot) of another version are rebuilt, not trusted: bump
    #: this whenever apply() or the fields below change meaning.
    snapshot_name: ClassVar[str] = "scene_graph"
    snapshot_version: ClassVar[int] = 1

    def to_snapshot(self) -> dict[str, Any]:
        return {
            "relations": [[d, s, v] for (d, s), v in sorted(self.relations.items())],
            "update_mode": self.update_mode.value,
            "tasks_folded": self.tasks_folded,
            "target": self._task.target,
            "experience": self._task.seen_at_rows(),
        }

    @classmethod
    def from_snapshot(cls, state: Mapping[str, Any], last_seq: int) -> SceneGraphProjection:
        return cls(
            relations={(d, s): float(v) for d, s, v in state["relations"]},
            update_mode=UpdateMode(state["update_mode"]),
            last_seq=last_seq,
            tasks_folded=int(state["tasks_folded"]),
            _task=TaskExperience(
                target=state["target"],
                seen_at=TaskExperience.seen_at_from(state["experience"]),
            ),
        )

    @property
    def state(self) -> Mapping[Pair, float]:
        """Rel per (dynamic, static) class pair, read-only (the ``Projection`` protocol's state)."""
        return MappingProxyType(self.relations)

    @property
    def experience(self) -> dict[str, frozenset[str]]:
        """The experience pool of the task in progress: class → static classes it was seen at."""
        return {d: frozenset(s) for d, s in self._task.seen_at.items()}

    def rel(self, dynamic: str, static: str) -> float:
        return self.relations.get((dynamic, static), 0.0)

    def as_table(self) -> dict[str, dict[str, float]]:
        table: dict[str, dict[str, float]] = {}
        for (d, s), value in sorted(self.relations.items()):
            table.setdefault(d, {})[s] = value
        return table
