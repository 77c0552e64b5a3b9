"""What an agent knows, as one projection of its log: the run's spec, its tasks, its memory.

:class:`AgentState` is the fold every reader uses — the agent on restart, replay, audit, the live
view, the report and the lake's derived tables — so they cannot disagree about what a log means:

- ``run``: the latest ``run_started`` as a :class:`~objsearch.agent.strategies.RunSpec`;
- ``model``: the relation model, built from the *first* run's spec (its model and parameters, as
  recorded) and fed every event; later runs may change the planner, α or update mode, never the fold;
- ``tasks``: the task ledger — task ids are numbered from the log (never from a counter inside
  the model), and a task that was started and never ended or aborted is ``open``.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from objsearch.agent.catalogue import Moved, RunStarted, SceneGraphSeeded, TaskStarted, decode
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.maps import MapEvidence
from objsearch.agent.relations import RelationModel
from objsearch.agent.scene_graph import SceneGraphProjection
from objsearch.agent.strategies import AGENT_MODELS, RelationModels, RelationSpec, RunSpec
from objsearch.events.projection import EventView

_TASK_NUMBER = re.compile(r"task-(\d+)")
#: The event types :class:`~objsearch.agent.maps.MapEvidence` reads.
_MAP_TYPES = frozenset({"run_started", "detection"})
#: The event types :meth:`TaskLedger.apply` reads.
_LEDGER_TYPES = frozenset({"task_started", "moved", "task_ended", "task_aborted"})


def _all(handlers: list[Callable[[Any], None]]) -> Callable[[Any], None]:
    """One handler that calls ``handlers`` in order (the order :meth:`AgentState.apply` has)."""
    if len(handlers) == 1:
        return handlers[0]
    first, *rest = handlers
    if len(rest) == 1:
        second = rest[0]

        def both(r: Any) -> None:
            first(r)
            second(r)

        return both

    def each(r: Any) -> None:
        for handler in handlers:
            handler(r)

    return each


@dataclass(frozen=True, slots=True)
class OpenTask:
    """A task started and not (yet) ended: in progress, or left open by a crash."""

    task_id: str
    target: str
    metres: float


@dataclass
class TaskLedger:
    """Task numbering and the task in progress, from ``task_started``/``task_ended``/``task_aborted``."""

    last_number: int = 0
    started: int = 0
    ended: int = 0
    aborted: int = 0
    open: OpenTask | None = None
    #: While a fold hands records to :meth:`record_handlers`: the open task's metres so far,
    #: summed as :meth:`apply` sums them, made an ``OpenTask`` once, by :meth:`settle` (one per
    #: ``moved`` cost 1 µs, a fifth of what the agent's fold spent per event). None: settled.
    _metres: float | None = field(default=None, compare=False, repr=False)

    def apply(self, event: EventView, task_id: str | None) -> None:
        kind = event.type
        if kind == "task_started" and task_id is not None:
            match = _TASK_NUMBER.fullmatch(task_id)
            if match:
                self.last_number = max(self.last_number, int(match.group(1)))
            self.started += 1
            self.open = OpenTask(task_id, decode(event, TaskStarted).target, 0.0)
        elif kind == "moved" and self.open is not None and task_id == self.open.task_id:
            self.open = OpenTask(
                self.open.task_id, self.open.target, self.open.metres + decode(event, Moved).metres
            )
        elif kind in ("task_ended", "task_aborted") and self.open is not None:
            if task_id == self.open.task_id:
                self.open = None
            if kind == "task_ended":
                self.ended += 1
            else:
                self.aborted += 1

    def record_handlers(self) -> dict[str, Callable[[Any], None]]:
        """:meth:`apply` per type, from a log's records (each handler gets the envelope with its
        payload decoded as the type's record)."""

        def started(r: Any) -> None:
            task_id = r.task_id
            if task_id is not None:
                match = _TASK_NUMBER.fullmatch(task_id)
                if match:
                    self.last_number = max(self.last_number, int(match.group(1)))
                self.started += 1
                self.open = OpenTask(task_id, r.payload.target, 0.0)
                self._metres = None

        def moved(r: Any) -> None:
            task = self.open
            if task is not None and r.task_id == task.task_id:
                metres = self._metres
                self._metres = (task.metres if metres is None else metres) + r.payload.metres

        def ended(r: Any) -> None:
            if self.open is not None:
                if r.task_id == self.open.task_id:
                    self.open = None
                    self._metres = None
                self.ended += 1

        def aborted(r: Any) -> None:
            if self.open is not None:
                if r.task_id == self.open.task_id:
                    self.open = None
                    self._metres = None
                self.aborted += 1

        return {"task_started": started, "moved": moved, "task_ended": ended,
                "task_aborted": aborted}  # fmt: skip

    def settle(self) -> None:
        """The open task as :meth:`apply` leaves it, after records were handed to the handlers."""
        metres = self._metres
        if metres is not None:
            task = self.open
            if task is not None:
                self.open = OpenTask(task.task_id, task.target, metres)
            self._metres = None

    def next_task_id(self) -> str:
        return f"task-{self.last_number + 1:05d}"


@dataclass
class AgentState:
    """The projection of an agent's log (see the module docstring)."""

    run: RunSpec | None = None
    first_run: RunSpec | None = None
    model: RelationModel | None = None
    tasks: TaskLedger = field(default_factory=TaskLedger)
    seeded: bool = False  # the Visual Genome prior was recorded (scene_graph_seeded)
    #: That event's ``source``: which reading of Eq. 2 the log's scene graph started from.
    seeded_source: str | None = None
    #: Fold with this relation model instead of the run's: a counterfactual, never the agent's
    #: own state (``objsearch replay --strategy``).
    counterfactual: RelationSpec | None = None
    #: Relation models outside the agent the log's spec may name (the simulator's dist-oracle).
    models: RelationModels = field(default_factory=lambda: AGENT_MODELS, repr=False, compare=False)
    #: The data folder a model that reads the home (the belief) reads it from (None:
    #: ``datapaths.data_dir()``): the run's, handed down, never set in the environment.
    data: Path | None = field(default=None, repr=False, compare=False)
    #: The map each session ran in and each class's sightings per map (agent/maps.py).
    maps: MapEvidence = field(default_factory=MapEvidence)
    last_seq: int = 0
    last_time_ns: int = 0
    #: :meth:`record_handlers`' last answer and the parts it was made of (made again if the
    #: model, the map evidence or the ledger is another object).
    _handlers: tuple[object, object, object, dict[str, Callable[[Any], None] | None] | None] = (
        field(default=(None, None, None, None), init=False, repr=False, compare=False)
    )

    snapshot_name: ClassVar[str] = "agent_state"
    # 2: sightings with position and ``at``; 3: oracle's today; 4: maps and their evidence
    snapshot_version: ClassVar[int] = 4

    @property
    def state(self) -> AgentState:
        return self

    def apply(self, event: EventView) -> None:
        kind = event.type
        if kind == "run_started":
            self.run = RunSpec.from_record(decode(event, RunStarted))
            if self.model is None:
                self.first_run = self.run
                relations = self.counterfactual or self.run.relations
                self.model = relations.build(self.models, data=self.data)
        elif kind == "scene_graph_seeded":
            self.seeded = True
            self.seeded_source = decode(event, SceneGraphSeeded).source
        model = self.model
        if model is not None:
            model.apply(event)
        if kind in _MAP_TYPES:
            self.maps.apply(event)
        if kind in _LEDGER_TYPES:  # the rest pass the ledger by (most of a log: detections)
            self.tasks.apply(event, getattr(event, "task_id", None))
        self.last_seq = event.seq
        self.last_time_ns = int(getattr(event, "time_ns", self.last_time_ns))

    def record_handlers(self) -> dict[str, Callable[[Any], None] | None] | None:
        """What :meth:`apply` does per type, from a log's records (``events.fold_read``), while
        the relation model can fold records too (None: fold events). ``run_started`` and
        ``scene_graph_seeded`` are folded as events (they build the model and happen once)."""
        model, maps, tasks = self.model, self.maps, self.tasks
        made = self._handlers
        if made[0] is model and made[1] is maps and made[2] is tasks and made[3] is not None:
            return made[3]
        map_handlers = maps.record_handlers()
        if model is None:
            model_handlers: dict[str, Callable[[Any], None]] = {}
        elif isinstance(model, SceneGraphProjection):
            # Eq. 4's model counts the detections' sightings in the map evidence too, in the
            # same call (the two in the order apply has them).
            model_handlers = model.record_handlers(sightings=maps)
            map_handlers = {k: h for k, h in map_handlers.items() if k != "detection"}
        else:
            handlers_of = getattr(model, "record_handlers", None)
            if handlers_of is None:
                return None
            model_handlers = handlers_of()
        handlers: dict[str, list[Callable[[Any], None]]] = {}
        for kind, handler in model_handlers.items():
            handlers.setdefault(kind, []).append(handler)
        for kind, handler in map_handlers.items():
            handlers.setdefault(kind, []).append(handler)
        for kind, handler in self.tasks.record_handlers().items():
            handlers.setdefault(kind, []).append(handler)
        out: dict[str, Callable[[Any], None] | None] = {k: _all(h) for k, h in handlers.items()}
        out["run_started"] = out["scene_graph_seeded"] = None
        self._handlers = (model, maps, tasks, out)
        return out

    def folded_to(self, seq: int, time_ns: int) -> None:
        # A model that folds records advances with them; one that does not was handed every
        # event since it was built (no record is folded while it is there).
        folded_to = getattr(self.model, "folded_to", None)
        if folded_to is not None:
            folded_to(seq, time_ns)
        self.tasks.settle()
        self.last_seq = seq
        self.last_time_ns = time_ns

    def graph(self) -> RelationModel:
        """The relation model; an error if the log has no run yet."""
        if self.model is None:
            raise ObjsearchError("the log holds no run_started yet: there is no scene graph")
        return self.model

    def to_snapshot(self) -> dict[str, Any]:
        model = self.model
        to_snapshot = getattr(model, "to_snapshot", None)
        if model is not None and to_snapshot is None:
            raise ObjsearchError(f"{type(model).__name__} cannot be snapshotted")
        open_task = self.tasks.open
        return {
            "run": None if self.run is None else self.run.payload(),
            "first_run": None if self.first_run is None else self.first_run.payload(),
            "model": None if to_snapshot is None else to_snapshot(),
            "tasks": {
                "last_number": self.tasks.last_number,
                "started": self.tasks.started,
                "ended": self.tasks.ended,
                "aborted": self.tasks.aborted,
                "open": None
                if open_task is None
                else [open_task.task_id, open_task.target, open_task.metres],
            },
            "seeded": self.seeded,
            "seeded_source": self.seeded_source,
            "last_time_ns": self.last_time_ns,
            "maps": self.maps.to_snapshot(),
            # Which model folded it, when not the run's own (a snapshot without the key: none).
            "counterfactual": None
            if self.counterfactual is None
            else dataclasses.asdict(self.counterfactual),
        }

    @classmethod
    def from_snapshot(
        cls,
        state: dict[str, Any],
        last_seq: int,
        models: RelationModels = AGENT_MODELS,
        data: Path | None = None,
    ) -> AgentState:
        first = None if state["first_run"] is None else RunSpec.from_payload(state["first_run"])
        cf = state.get("counterfactual")
        counterfactual = None if cf is None else RelationSpec(**cf)
        model = None
        if first is not None:
            fresh = (counterfactual or first.relations).build(models, data=data)
            restore = getattr(type(fresh), "from_snapshot", None)
            if restore is None:
                raise ObjsearchError(f"{type(fresh).__name__} cannot be restored")
            model = restore(state["model"], last_seq)
        t = state["tasks"]
        open_task = None if t["open"] is None else OpenTask(*t["open"])
        return cls(
            run=None if state["run"] is None else RunSpec.from_payload(state["run"]),
            first_run=first,
            model=model,
            tasks=TaskLedger(t["last_number"], t["started"], t["ended"], t["aborted"], open_task),
            seeded=bool(state["seeded"]),
            # Snapshots written before the source was kept lack it: unknown, not checked.
            seeded_source=state.get("seeded_source"),
            counterfactual=counterfactual,
            models=models,
            data=data,
            maps=MapEvidence.from_snapshot(state["maps"]),
            last_seq=last_seq,
            last_time_ns=int(state["last_time_ns"]),
        )
