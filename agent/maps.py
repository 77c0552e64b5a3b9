"""Map identity: which map a session ran in, and which map each piece of evidence was gathered in.

Every session runs in a map. ``run_started.params.map`` names it; a run that records none ran in
:data:`DEFAULT_MAP`, the map its home was first given (so logs from before maps had ids read
as they always did). A session that starts in a new map (``objsearch search --new-map``, ``bench
homes --new-map-day N``) records the next id (:func:`next_map`).

Positions are in a map's frame, so evidence gathered in a map the robot has since left cannot be
trusted silently: :class:`MapEvidence` (part of :class:`~objsearch.agent.state.AgentState`) keeps,
for each object class, how many accepted sightings each map gave and when the latest was, and
``where`` flags an answer that rests on another map's evidence. What carries over is what is
anchored to a static object by its id (the belief counts places by static id): re-anchored when
the new map names the same statics. A new map with a frame of its own is registered to the
agent's working frame by its statics (agent/map_frames.py), so positions are re-anchored too.
"""

from __future__ import annotations

import bisect
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Final, NamedTuple

from objsearch.agent.catalogue import Detected, RunStarted, decode
from objsearch.agent.task_experience import SeenBy, TaskExperience
from objsearch.events.projection import EventView

#: The map of a run that records none.
DEFAULT_MAP = "map-0"
_NUMBERED = re.compile(r"(.*?)(\d+)")


def map_of(params: Mapping[str, Any]) -> str:
    """The map a run spec's ``params`` say it ran in."""
    return str(params.get("map") or DEFAULT_MAP)


def next_map(current: str) -> str:
    """The id of the map after ``current``: its number plus one (``map-0`` → ``map-1``)."""
    match = _NUMBERED.fullmatch(current)
    if match is None:
        return f"{current}-1"
    return f"{match.group(1)}{int(match.group(2)) + 1}"


class MapSightings(NamedTuple):
    """The accepted sightings of one class gathered in one map (a tuple: one is made per
    accepted detection a fold reads, and a frozen dataclass's ``__init__`` costs twice as much)."""

    sightings: int
    latest_ns: int
    latest_task: str | None


#: ``MapSightings(...)`` made in C (the named tuple's own ``__new__`` is Python: 0.5 against
#: 0.2 µs, once per accepted detection a fold reads from records).
_sightings: Final = partial(tuple.__new__, MapSightings)


@dataclass
class MapEvidence:
    """The map each session ran in, and each class's sightings per map (a fold of the log)."""

    current: str | None = None
    #: (first event time, map) of each change of map, in log order.
    changes: list[tuple[int, str]] = field(default_factory=list)
    by_class: dict[str, dict[str, MapSightings]] = field(default_factory=dict)

    def apply(self, event: EventView) -> None:
        # The records, not the payload dicts: the agent's state decodes each event once, and its
        # relation model reads the same detection record (catalogue.decode keeps it).
        kind = event.type
        if kind == "run_started":
            chosen = map_of(decode(event, RunStarted).params or {})
            if chosen != self.current:
                self.current = chosen
                self.changes.append((int(getattr(event, "time_ns", 0)), chosen))
        elif kind == "detection" and self.current is not None:
            detected = decode(event, Detected)
            if not detected.accepted:
                return
            per = self.by_class.setdefault(detected.object_class, {})
            before = per.get(self.current)
            count = 1 if before is None else before.sightings + 1
            per[self.current] = MapSightings(
                count, int(getattr(event, "time_ns", 0)), getattr(event, "task_id", None)
            )

    def record_handlers(
        self, experience: TaskExperience | None = None
    ) -> dict[str, Callable[[Any], None]]:
        """:meth:`apply`'s detections, from a log's records (``run_started`` changes the map and
        is folded as an event). With ``experience`` (the task in progress of the relation model
        beside this evidence, counting sightings by class), each detection is folded into it
        too, as :meth:`TaskExperience.record_handler <.task_experience.TaskExperience.record_handler>`
        folds it, in the same call: the agent's state reads every detection of a log in both,
        and one call in place of three (the two and the call of both) was 4 % of its fold."""
        by_class = self.by_class
        if experience is not None and experience.seen_by is SeenBy.CLASS:
            return {"detection": self._detection_and_experience(experience)}

        def detection(r: Any) -> None:
            current = self.current
            if current is None:
                return
            detected = r.payload
            if not detected.accepted:
                return
            per = by_class.setdefault(detected.object_class, {})
            before = per.get(current)
            count = 1 if before is None else before.sightings + 1
            per[current] = _sightings((count, r.time_ns, r.task_id))

        return {"detection": detection}

    def _detection_and_experience(self, experience: TaskExperience) -> Callable[[Any], None]:
        """One handler: the detection into ``experience`` (by class), then into this evidence
        (the order of :meth:`AgentState.apply <objsearch.agent.state.AgentState.apply>`)."""
        by_class = self.by_class

        def detection(r: Any) -> None:
            detected = r.payload
            if not detected.accepted:
                return
            cls = detected.object_class
            support = detected.support
            statics = experience.seen_at.setdefault(cls, set())
            if support is not None and support.at:
                statics.add(support.static_class)
            current = self.current
            if current is None:
                return
            per = by_class.setdefault(cls, {})
            before = per.get(current)
            count = 1 if before is None else before.sightings + 1
            per[current] = _sightings((count, r.time_ns, r.task_id))

        return detection

    def map_at(self, time_ns: int) -> str | None:
        """The map the robot was in at ``time_ns`` (None: before any run)."""
        k = bisect.bisect_right([t for t, _ in self.changes], time_ns)
        return self.changes[k - 1][1] if k else None

    def map_of_sighting(self, cls: str, task_id: str | None, time_ns: int) -> str | None:
        """The map a sighting of ``cls`` (in ``task_id`` at ``time_ns``) was gathered in: the map
        whose latest sighting it is, else the map the robot was in at that time."""
        for chosen, s in self.by_class.get(cls, {}).items():
            if s.latest_task == task_id and s.latest_ns == time_ns:
                return chosen
        return self.map_at(time_ns)

    def left(self) -> list[str]:
        """Maps the robot ran in and has since left, in the order it left them."""
        seen = list(dict.fromkeys(m for _, m in self.changes))
        return [m for m in seen if m != self.current]

    def to_snapshot(self) -> dict[str, Any]:
        return {
            "current": self.current,
            "changes": [[t, m] for t, m in self.changes],
            "by_class": {
                cls: {m: [s.sightings, s.latest_ns, s.latest_task] for m, s in per.items()}
                for cls, per in self.by_class.items()
            },
        }

    @classmethod
    def from_snapshot(cls, doc: Mapping[str, Any]) -> MapEvidence:
        return cls(
            current=doc["current"],
            changes=[(int(t), str(m)) for t, m in doc["changes"]],
            by_class={
                c: {m: MapSightings(int(n), int(t), task) for m, (n, t, task) in per.items()}
                for c, per in doc["by_class"].items()
            },
        )
