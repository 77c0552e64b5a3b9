"""``objsearch where TARGET``: where an object was last seen, where it usually is, how sure —
answered from the belief of a log (:class:`~objsearch.agent.belief.PlaceBelief`): probabilities
per place and per room that sum, with "elsewhere" (at no mapped place), to one.

"Elsewhere" is one mass in the belief, with no room of its own: the answer gives it the room of the
object's latest sighting when that sighting was away from every mapped place (``elsewhere_room``),
and counts it in that room's probability; otherwise its room is not known (null) and it stays apart.
Older sightings away from the mapped places are not located (the fold keeps only the latest).

One fold answers every way of asking: a log folder and a lake run (``objsearch where``) are folded
by :func:`where`, and the running agent keeps the same projection live (:class:`LiveMemory`,
``objsearch agent where``), so the three cannot disagree about the same events.

The belief is the one that knows the hour (:class:`~objsearch.agent.routine_belief.RoutineBelief`):
``at`` asks for another time of day (``objsearch where --at "sat 09:00"``; the default, ``None``,
is the time of the log's latest search); a log whose searches record no time of day folds to the
time-blind belief exactly, and its answer says so (``time_of_day`` null).

A log whose run used another relation model is folded with that belief as a counterfactual
(``AgentState(counterfactual=ROUTINE_BELIEF)``): the facts it answers from (sightings, looks) are in every
log; only the robot's own plans used another model, and the answer says so (``model_of_run``).
"""

from __future__ import annotations

import threading
from collections.abc import Iterable
from pathlib import Path
from typing import Any, ClassVar

from objsearch.agent.belief import ELSEWHERE, PlaceBelief
from objsearch.agent.catalogue import STORE, DayClock
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.home import Home, load_home
from objsearch.agent.navmap import NavigationMap
from objsearch.agent.routine_belief import RoutineBelief, buckets_of
from objsearch.agent.sightings import Sighting
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import ROUTINE_BELIEF
from objsearch.events.envelope import Event
from objsearch.events.errors import ProjectionError
from objsearch.events.hub import Member
from objsearch.events.log import EventLog
from objsearch.events.projection import EventView, fold
from objsearch.events.snapshot import restore, save_snapshot


def memory_state(events: Iterable[Event]) -> AgentState:
    """The projection ``where`` answers from: ``events`` folded with the belief."""
    return fold(events, _fresh())


def where(
    events: Iterable[Event], target: str, *, top: int = 3, at: DayClock | None = None
) -> dict[str, Any]:
    """The answer for ``target`` from a log's or a lake run's events, at the time of day ``at``
    (None: the time of the latest search)."""
    state = memory_state(events)
    if state.run is None:
        raise ObjsearchError("the events hold no run yet: nothing has been searched")
    return answer(state, target, load_home(state.run.home), top=top, at=at)


def answer(
    state: AgentState, target: str, home: Home, *, top: int = 3, at: DayClock | None = None
) -> dict[str, Any]:
    """What the folded ``state`` says about ``target`` (``home``: the run's, for rooms) at the
    time of day ``at`` (None: the time of the latest search)."""
    belief = state.graph()
    assert isinstance(belief, PlaceBelief)
    assert state.run is not None
    known = sorted({d for d, _ in belief.prior})
    if target not in known:
        raise ObjsearchError(
            f"unknown object class {target!r} in this run's scene graph; known: {', '.join(known)}"
        )
    statics = home.statics
    dist, time_of_day = _distribution(belief, target, at)
    places = sorted((p for p in dist if p in statics), key=lambda p: (-dist[p], p))
    rooms: dict[str, float] = {}
    for p in places:
        rooms[statics[p].room] = rooms.get(statics[p].room, 0.0) + dist[p]
    counts = belief.long.get(target)
    usual = None
    if counts is not None and counts.at:
        usual = max(sorted(counts.at), key=counts.at.__getitem__)
    last = belief.sightings.last.get(target)
    last_room = None if last is None else _room_of(last, home)
    elsewhere = dist.get(ELSEWHERE, 0.0)
    # The belief's elsewhere has no room; the latest sighting, when it was away from every mapped
    # place, says where the mass it put there is (a sighting in the kitchen gave the kitchen 0.0 %).
    elsewhere_room = last_room if last is not None and not last.at else None
    if elsewhere_room is not None:
        rooms[elsewhere_room] = rooms.get(elsewhere_room, 0.0) + elsewhere
    weights = belief.weights.get(target, (1 / 3, 1 / 3, 1 / 3))
    maps = map_answer(state, target)
    last_outcome = belief.last_outcome.get(target)
    return {
        "target": target,
        # The run id names the run, not the file it was read from: a log and the lake run made
        # from it give the same answer.
        "run_id": state.run.params.get("run_id"),
        "model_of_run": state.run.relations.model,
        "tasks": belief.tasks_folded,
        # The time of day answered for; null when the log records none (the time-blind answer).
        "time_of_day": time_of_day,
        "last_seen": None if last is None else _last_seen(state, target, last, last_room),
        "map": maps,
        # Every mapped place the belief gives mass, over which (with elsewhere) it sums to one.
        "belief_over_places": len(places),
        # Away from every mapped place; its room when the latest sighting was there (null: not
        # known). rooms counts it in that room, so rooms sum to one less an unlocated elsewhere.
        "elsewhere": round(elsewhere, 4),
        "elsewhere_room": elsewhere_room,
        "evidence": {
            "episodes": round(counts.total, 3) if counts is not None else 0.0,
            "episodes_since_last": None
            if last_outcome is None
            else belief.episodes - 1 - last_outcome,
            "weights": {
                "long": round(weights[0], 4),
                "short": round(weights[1], 4),
                "yesterday": round(weights[2], 4),
            },
        },
        "usually": None
        if usual is None or counts is None
        else {
            "static_id": usual,
            "room": statics[usual].room if usual in statics else elsewhere_room,
            "episodes": round(counts.at[usual], 3),
            "share_of_episodes": round(counts.at[usual] / counts.total, 4),
        },
        "rooms": [
            {"room": r, "probability": round(v, 4)}
            for r, v in sorted(rooms.items(), key=lambda rv: (-rv[1], rv[0]))
            if v > 0
        ],
        "most_likely_now": [
            {
                "static_id": p,
                "static_class": statics[p].cls,
                "room": statics[p].room,
                "probability": round(dist[p], 4),
            }
            for p in places[:top]
        ],
    }


def _distribution(
    belief: PlaceBelief, target: str, at: DayClock | None
) -> tuple[dict[str, float], dict[str, Any] | None]:
    """``target``'s distribution over places at the time of day ``at`` (None: the belief's own
    clock), and the time of day answered for (None when the belief knows no hours)."""
    if not isinstance(belief, RoutineBelief):  # a snapshot from before the belief knew the hour
        return belief.distribution(target), None
    dist = belief.distribution_at(target, at)
    when = at or belief.clock
    if not belief.knows_hours or when is None:
        return dist, None
    return dist, {
        "weekday": when.weekday,
        "minute": when.minute,
        "slot": buckets_of(when)[1],
        "weights": {c: round(w, 4) for c, w in belief.component_weights(target).items()},
    }


def _room_of(last: Sighting, home: Home) -> str | None:
    """The room of a sighting: its static's, else the map's room at its position (or None)."""
    statics = home.statics
    if last.static_id in statics:
        return statics[last.static_id].room
    if last.position is not None:
        # Rare (a sighting away from every static): the map is built only then (~12 ms).
        return NavigationMap.from_home(home).room_at(last.position[0], last.position[1])
    return None


def _last_seen(state: AgentState, target: str, last: Sighting, room: str | None) -> dict[str, Any]:
    """The answer's ``last_seen``: ``target``'s latest sighting, in ``room``."""
    last_map = state.maps.map_of_sighting(target, last.task_id, last.time_ns)
    return {
        # at: it stood at static_id's viewpoint (a mapped place, what the belief counts);
        # otherwise static_id is only the nearest static of its room (or null).
        "static_id": last.static_id,
        "static_class": last.static_class,
        "at": last.at,
        "position": None if last.position is None else [round(v, 3) for v in last.position],
        "room": room,
        "task_id": last.task_id,
        "time_ns": last.time_ns,
        "scene": last.scene,
        # Seconds from the sighting to the log's latest event, and the map it was made in.
        "age_s": _age_s(state, last.time_ns),
        "map": last_map,
        "map_left": last_map is not None and last_map != state.maps.current,
    }


class LiveMemory:
    """The ``where`` projection kept live beside a running agent: restored once at start (from
    its snapshot and the events after it, like the agent's own state), then fed every event the
    agent appends (an observer of its session), and asked from another thread (the request
    server's) under a lock — so a question never re-reads the log and is answered even while a
    search is running.

    In the running agent it is a member of the session's projection hub (:meth:`member`):
    restored from the hub's one snapshot and fed from the hub, beside the agent's own state."""

    snapshot_name: ClassVar[str] = "where_memory"
    snapshot_version: ClassVar[int] = AgentState.snapshot_version

    def __init__(self, state: AgentState, home: Home) -> None:
        self._state = state
        self._home = home
        self._lock = threading.Lock()

    @classmethod
    def member(cls, home: Home, name: str = "where") -> Member[LiveMemory]:
        """The memory as a projection hub's member (``Session.open(projections=...)``)."""
        return Member(
            name,
            lambda: cls(_fresh(), home),
            lambda doc, seq: cls(AgentState.from_snapshot(doc, seq), home),
        )

    def to_snapshot(self) -> dict[str, Any]:
        with self._lock:
            return self._state.to_snapshot()

    @classmethod
    def restore(cls, log_dir: Path, home: Home, snapshot_dir: Path) -> LiveMemory:
        """From the snapshot in ``snapshot_dir`` (if trusted) and the log after it; a log that
        does not exist yet starts empty."""
        if not (log_dir / "meta.json").exists():
            return cls(_fresh(), home)
        state, _ = restore(
            log_dir,
            _fresh,
            AgentState.from_snapshot,
            snapshot_dir=snapshot_dir,
            save=False,
            store=STORE,
        )
        return cls(state, home)

    def save(self, snapshot_dir: Path, *, log: EventLog | Path) -> None:
        """A snapshot for the next :meth:`restore`, attested by ``log`` (the running agent's
        writer, or the folder of a log no one writes)."""
        with self._lock:
            save_snapshot(snapshot_dir, self._state, log=log, store=STORE)

    @property
    def last_seq(self) -> int:
        return self._state.last_seq

    @property
    def state(self) -> AgentState:
        return self._state

    def apply(self, event: EventView) -> None:
        with self._lock:
            expected = self._state.last_seq + 1
            if event.seq != expected:  # no event skipped or applied twice
                raise ProjectionError(
                    f"the where memory is at seq {expected - 1} and cannot apply seq {event.seq}"
                )
            self._state.apply(event)

    def answer(self, target: str) -> dict[str, Any]:
        with self._lock:
            if self._state.run is None:
                raise ObjsearchError("the agent has not started a run yet")
            return answer(self._state, target, self._home)


def _age_s(state: AgentState, time_ns: int) -> float:
    return round(max(0, state.last_time_ns - time_ns) / 1e9, 3)


def map_answer(state: AgentState, target: str) -> dict[str, Any]:
    """The map the robot is in now, the maps the evidence about ``target`` was gathered in (each
    with its sightings and the age of its latest), and the flag: set when any of it comes from
    a map the robot has since left (agent/maps.py says what carries over)."""
    current = state.maps.current
    per = state.maps.by_class.get(target, {})
    evidence = [
        {
            "map": m,
            "sightings": s.sightings,
            "latest_time_ns": s.latest_ns,
            "age_s": _age_s(state, s.latest_ns),
            "current": m == current,
        }
        for m, s in sorted(per.items(), key=lambda ms: -ms[1].latest_ns)
    ]
    stale = [e for e in evidence if not e["current"]]
    flag = None
    if stale:
        old = ", ".join(f"{e['map']} ({e['sightings']} sightings)" for e in stale)
        flag = (
            f"rests on evidence from {old}, a map the robot has left (now in {current}): "
            "places carried over by their static's id, positions not re-anchored"
        )
    return {"current": current, "evidence": evidence, "flagged": bool(stale), "flag": flag}


def _age(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 2 * 3600:
        return f"{seconds / 60:.0f} min"
    if seconds < 2 * 86400:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.1f} days"


def _fresh() -> AgentState:
    return AgentState(counterfactual=ROUTINE_BELIEF)


def _task(seen: dict[str, Any]) -> str:
    """(task T, scene N) of a sighting; a search run outside a schedule has no scene."""
    scene = "" if seen["scene"] is None else f", scene {seen['scene']}"
    return f"(task {seen['task_id']}{scene})"


def _elsewhere(answer: dict[str, Any]) -> str:
    room = answer.get("elsewhere_room")
    return "away from every mapped place" + (
        f", in {room}" if room is not None else " (room not known)"
    )


def _when(seen: dict[str, Any]) -> str:
    """How old a sighting is and the map it was made in (answers from before maps: nothing)."""
    if "age_s" not in seen:
        return ""
    left = ", a map the robot has left" if seen.get("map_left") else ""
    return f", {_age(seen['age_s'])} ago in {seen['map']}{left}"


def _map_lines(maps: dict[str, Any] | None) -> list[str]:
    if maps is None:
        return []
    gathered = "; ".join(
        f"{e['map']}{' (now)' if e['current'] else ''}: {e['sightings']} sighting(s), latest "
        f"{_age(e['age_s'])} ago"
        for e in maps["evidence"]
    )
    lines = [f"  map:       now {maps['current']}; evidence " + (gathered or "none yet")]
    if maps["flagged"]:
        lines.append(f"  FLAGGED:   {maps['flag']}")
    return lines


def render(answer: dict[str, Any]) -> str:
    """The answer as text (never "None": a missing room or scene is said or left out)."""
    lines = [f"{answer['target']} ({answer['tasks']} searches folded)"]
    when = answer.get("time_of_day")
    if when is not None:
        days = ("Mon", "Tue", "Wed", "Thu", "Fri", "Sat", "Sun")
        w = when["weights"]
        lines.append(
            f"  at:        {days[when['weekday']]} {when['minute'] // 60:02d}:{when['minute'] % 60:02d}"
            f" ({when['slot']}); trusting the time-blind memory {w['blind']:.0%}, the slot's "
            f"{w['slot']:.0%}, the slot's on this kind of day {w['slot_day']:.0%}"
        )
    last = answer["last_seen"]
    if last is None:
        lines.append("  last seen: never")
    elif last.get("at", True):
        lines.append(
            f"  last seen: {last['static_id']} in {last['room']} {_task(last)}{_when(last)}"
        )
    else:
        x, y, _ = last["position"]
        near = "" if last["static_id"] is None else f", nearest static {last['static_id']}"
        room = "" if last["room"] is None else f" in {last['room']}"
        lines.append(
            f"  last seen: away from every mapped place, at ({x:.2f}, {y:.2f}){room}{near} "
            f"{_task(last)}{_when(last)}"
        )
    lines.extend(_map_lines(answer.get("map")))
    usual = answer["usually"]
    if usual is not None:
        place = (
            _elsewhere(answer)
            if usual["static_id"] == ELSEWHERE
            else f"{usual['static_id']} in {usual['room']}"
        )
        lines.append(
            f"  usually:   {place} "
            f"(seen there in {usual['episodes']:g} of {answer['evidence']['episodes']:g} days, "
            f"{usual['share_of_episodes']:.0%})"
        )
    evidence = answer["evidence"]
    if evidence["episodes_since_last"] is not None:
        w = evidence["weights"]
        n = evidence["episodes_since_last"]
        latest = "the last day before today" if n == 0 else f"{n} day(s) before the last"
        lines.append(
            f"  evidence:  its latest from {latest}; trusting the long memory {w['long']:.0%}, "
            f"the recent {w['short']:.0%}, yesterday {w['yesterday']:.0%}"
        )
    located = answer.get("elsewhere_room") is not None
    if answer["rooms"]:
        rooms = ", ".join(f"{r['room']} {r['probability']:.1%}" for r in answer["rooms"])
        apart = (
            f" ({answer['elsewhere_room']}'s counts {answer['elsewhere']:.1%} away from every "
            "mapped place)"
            if located
            else f"; elsewhere (room not known) {answer['elsewhere']:.1%}"
        )
        lines.append(f"  rooms:     {rooms}{apart}")
    ranked = [
        (p["probability"], f"{p['static_id']} in {p['room']}") for p in answer["most_likely_now"]
    ]
    if ranked:
        lines.append(
            f"  most likely now (probabilities over the {answer['belief_over_places']} places "
            "it could be at, and elsewhere):"
        )
        # Elsewhere in its rank, when it outweighs a place listed.
        if answer["elsewhere"] > ranked[-1][0]:
            ranked = sorted(
                [*ranked, (answer["elsewhere"], _elsewhere(answer))], key=lambda r: -r[0]
            )
    for probability, place in ranked:
        lines.append(f"  {probability:6.1%}  {place}")
    return "\n".join(lines)
