"""Where each class was last seen: a fact of the log, whatever a model believes.

:class:`LastSeen` folds every accepted detection into a :class:`Sighting` (at a mapped place or away
from all of them, with its position) and makes it the last one when its search ends (a search cut
short by a crash folds nothing of its own). The memory and the belief both keep one, so ``where``
reports the same last sighting whichever answers.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from objsearch.agent.catalogue import Detected, TaskStarted, decode
from objsearch.events.projection import EventView


@dataclass(frozen=True, slots=True)
class Sighting:
    """Where a class was last seen: the nearest static instance and its class (None in a room
    with none), whether it stood at that static (``at``: what the belief counts) or away from
    every mapped place, its position (map frame, metres), and when."""

    static_id: str | None
    static_class: str | None
    task_id: str | None
    time_ns: int
    scene: int | None
    at: bool = True
    position: tuple[float, float, float] | None = None


@dataclass
class LastSeen:
    """The last sighting per class, and the running search's (counted when it ends)."""

    last: dict[str, Sighting] = field(default_factory=dict)
    task_id: str | None = None
    scene: int | None = None
    pending: dict[str, Sighting] = field(default_factory=dict)

    def apply(self, event: EventView) -> None:
        kind = event.type
        if kind == "task_started":
            self.task_id = getattr(event, "task_id", None)
            self.scene = decode(event, TaskStarted).scene
            self.pending = {}
        elif kind == "detection":
            detected = decode(event, Detected)
            if detected.accepted:
                support = detected.support
                self.pending[detected.object_class] = Sighting(
                    None if support is None else support.static_id,
                    None if support is None else support.static_class,
                    self.task_id,
                    int(getattr(event, "time_ns", 0)),
                    self.scene,
                    support is not None and support.at,
                    (
                        float(detected.position[0]),
                        float(detected.position[1]),
                        float(detected.position[2]),
                    ),
                )
        elif kind == "task_ended":
            self.last.update(self.pending)
            self.pending = {}
        elif kind == "task_aborted":
            self.pending = {}

    def to_snapshot(self) -> dict[str, Any]:
        return {
            "last_seen": {d: list(sighting_row(s)) for d, s in sorted(self.last.items())},
            "sightings": {d: list(sighting_row(s)) for d, s in sorted(self.pending.items())},
            "task_id": self.task_id,
            "scene": self.scene,
        }

    @classmethod
    def from_snapshot(cls, state: Mapping[str, Any]) -> LastSeen:
        return cls(
            last={d: sighting(r) for d, r in state["last_seen"].items()},
            task_id=state["task_id"],
            scene=state["scene"],
            pending={d: sighting(r) for d, r in state["sightings"].items()},
        )


def sighting_row(s: Sighting) -> tuple[Any, ...]:
    position = None if s.position is None else list(s.position)
    return (s.static_id, s.static_class, s.task_id, s.time_ns, s.scene, s.at, position)


def sighting(row: list[Any]) -> Sighting:
    static_id, static_class, task_id, time_ns, scene, at, position = row
    return Sighting(
        static_id,
        static_class,
        task_id,
        int(time_ns),
        scene,
        bool(at),
        None if position is None else (float(position[0]), float(position[1]), float(position[2])),
    )
