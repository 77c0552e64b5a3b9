"""Where a search's excess over the oracle went, exactly, from its event log.

Every ``moved`` leg of a task is charged to the room it *ends* in (the room the robot was walking
to search; a leg cut short because the target came into view ends where it stopped). With R the
room the target was found from (where the final approach ends):

- ``wrong_rooms``: metres of legs ending in a room other than R;
  ``start_room`` (part of it): legs ending in the start room when that was not R;
- ``right_room``: legs ending in R, minus the final approach, minus the oracle's walk;
- ``approach``: the final approach (the last ``moved`` before ``target_found``).

So ``wrong_rooms + right_room + approach == path − oracle`` for every successful search. The
oracle walk is subtracted from the right-room part (the oracle ends in R): a search that entered R
through another room shows a small negative ``right_room`` and that walk under ``wrong_rooms``.
Failed searches are not decomposed (their excess has no oracle end).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from objsearch.agent.catalogue import Moved, PlanarPose, TargetFound, TaskStarted, decode
from objsearch.agent.navmap import NavigationMap
from objsearch.events.projection import EventView


@dataclass(frozen=True, slots=True)
class Excess:
    """One successful search's walk, by where it went (metres; see the module doc)."""

    wrong_rooms: float
    start_room: float
    right_room_walk: float
    approach: float

    def right_room(self, oracle: float) -> float:
        return self.right_room_walk - oracle


def _room(navmap: NavigationMap, pose: PlanarPose) -> str:
    return navmap.room_at(pose.x, pose.y)


def decompose(events: Iterable[EventView], navmap: NavigationMap) -> dict[str, Excess]:
    """task id → the walk decomposition of each successful task of a log."""
    out: dict[str, Excess] = {}
    legs: list[tuple[str, float]] = []
    start_room = ""
    for e in events:
        if e.task_id is None:
            continue
        if e.type == "task_started":
            legs = []
            start_room = _room(navmap, decode(e, TaskStarted).pose)
        elif e.type == "moved":
            moved = decode(e, Moved)
            legs.append((_room(navmap, moved.end), moved.metres))
        elif e.type == "target_found":
            found_room = _room(navmap, decode(e, TargetFound).approach)
            approach = legs[-1][1] if legs else 0.0
            wrong = sum(m for r, m in legs if r != found_room)
            start = sum(m for r, m in legs if r != found_room and r == start_room)
            right = sum(m for r, m in legs[:-1] if r == found_room)
            out[e.task_id] = Excess(wrong, start, right, approach)
    return out
