"""Event logs of searches for the belief tests (time-blind and time-aware), numbered, with an
optional time of day per search."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field

from objsearch.agent.belief import Place, PlaceBelief
from objsearch.agent.catalogue import (
    DayClock,
    PlanarPose,
    Record,
    SceneGraphSeeded,
    SeedValue,
    TaskEnded,
    TaskStarted,
    ViewTaken,
)
from objsearch.experiments.dhs import RecordEvent, sighting

PLACES = {
    "counter-a": Place("counter-a", "CounterTop", "kitchen"),
    "counter-b": Place("counter-b", "CounterTop", "kitchen"),
    "table": Place("table", "DiningTable", "living"),
    "shelf": Place("shelf", "Shelf", "living"),
}
ORIGIN = PlanarPose(x=0.0, y=0.0, yaw=0.0)


@dataclass
class Log:
    """Builds the events a search writes, numbered."""

    events: list[RecordEvent] = field(default_factory=list)
    tasks: int = 0

    def add(self, record: Record, task_id: str | None = None) -> None:
        self.events.append(RecordEvent.of(len(self.events) + 1, record, task_id))

    def search(
        self,
        target: str,
        scene: int | None,
        *,
        looks: tuple[str, ...] = (),
        found: str | None = None,
        also_seen: Mapping[str, str] | None = None,
        clock: DayClock | None = None,
    ) -> None:
        """One search: views of ``looks`` (none of which held it), then ``found`` if given."""
        self.tasks += 1
        task = f"t{self.tasks}"
        self.add(TaskStarted(target=target, start="s", pose=ORIGIN, scene=scene, clock=clock), task)
        for place in looks:
            self.add(ViewTaken(pose=ORIGIN, pitch=0.5, static_id=place, reason="look"), task)
        for cls, place in (also_seen or {}).items():
            self._detect(cls, place, task)
        if found is not None:
            self.add(ViewTaken(pose=ORIGIN, pitch=0.5, static_id=found, reason="look"), task)
            self._detect(target, found, task)
        self.add(TaskEnded(target=target, success=found is not None, path_length=1.0), task)

    def _detect(self, cls: str, place: str, task: str) -> None:
        self.add(sighting(cls, f"{cls}|1", place, PLACES[place].static_class), task)


def fold_into(belief: PlaceBelief, log: Log) -> PlaceBelief:
    """``belief`` (over :data:`PLACES`) with the seed and ``log`` folded into it."""
    belief.places = dict(PLACES)
    for event in with_seed(log):
        belief.apply(event)
    return belief


def with_seed(log: Log) -> Iterator[RecordEvent]:
    values = (
        SeedValue(dynamic="Cup", static="CounterTop", rel=0.5),
        SeedValue(dynamic="Cup", static="DiningTable", rel=0.25),
        SeedValue(dynamic="Apple", static="CounterTop", rel=0.4),
        SeedValue(dynamic="Apple", static="DiningTable", rel=0.4),
    )
    yield RecordEvent.of(0, SceneGraphSeeded(source="test", values=values))
    yield from log.events
