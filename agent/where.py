"""``objsearch where TARGET``: where an object was last seen, where it usually is, how sure —
answered from the memory projection of a log (:class:`~objsearch.agent.memory.InstanceMemory`).

A log whose run used another relation model is folded with the memory model as a counterfactual
(``AgentState(counterfactual=MEMORY)``): the facts it answers from (sightings, looks) are in every
log; only the robot's own plans used another model, and the answer says so.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from objsearch.agent.errors import ObjsearchError
from objsearch.agent.home import load_home
from objsearch.agent.memory import InstanceMemory
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import MEMORY
from objsearch.events.log import read_log
from objsearch.events.projection import fold


@dataclass(frozen=True, slots=True)
class Place:
    static_id: str
    static_class: str
    room: str
    belief: float  # share of the memory's mass over every known static


def where(log_dir: Path, target: str, *, top: int = 3) -> dict[str, Any]:
    state = fold(read_log(log_dir), AgentState(counterfactual=MEMORY))
    if state.run is None:
        raise ObjsearchError(f"{log_dir}: the log holds no run yet")
    memory = state.graph()
    assert isinstance(memory, InstanceMemory)
    if target not in {d for d, _ in memory.classes.prior}:
        raise ObjsearchError(f"unknown object class {target!r} in this log's scene graph")
    statics = load_home(state.run.home).statics
    values = {sid: v for sid, v in memory.instances(target).items() if v > 0 and sid in statics}
    total = sum(values.values())
    ranked = sorted(values, key=lambda s: (-values[s], s))[:top]
    likely = [
        Place(s, statics[s].cls, statics[s].room, values[s] / total if total else 0.0)
        for s in ranked
    ]
    counts = {sid: n for (d, sid), n in memory.seen.items() if d == target}
    usual = max(sorted(counts), key=counts.__getitem__) if counts else None
    last = memory.last_seen.get(target)
    return {
        "target": target,
        "log": str(log_dir),
        "model_of_run": state.run.relations.model,
        "tasks": memory.tasks_folded,
        "last_seen": None
        if last is None
        else {
            "static_id": last.static_id,
            "static_class": last.static_class,
            "room": statics[last.static_id].room if last.static_id in statics else None,
            "task_id": last.task_id,
            "time_ns": last.time_ns,
            "scene": last.scene,
        },
        "usually": None
        if usual is None
        else {
            "static_id": usual,
            "room": statics[usual].room if usual in statics else None,
            "seen_tasks": counts[usual],
            "share_of_sightings": counts[usual] / sum(counts.values()),
        },
        "most_likely_now": [
            {
                "static_id": p.static_id,
                "static_class": p.static_class,
                "room": p.room,
                "belief": round(p.belief, 4),
            }
            for p in likely
        ],
    }


def render(answer: dict[str, Any]) -> str:
    lines = [f"{answer['target']} ({answer['tasks']} searches folded)"]
    last = answer["last_seen"]
    lines.append(
        "  last seen: never"
        if last is None
        else f"  last seen: {last['static_id']} in {last['room']} "
        f"(task {last['task_id']}, scene {last['scene']})"
    )
    usual = answer["usually"]
    if usual is not None:
        lines.append(
            f"  usually:   {usual['static_id']} in {usual['room']} "
            f"(seen there in {usual['seen_tasks']:g} searches, "
            f"{usual['share_of_sightings']:.0%} of its sightings)"
        )
    for p in answer["most_likely_now"]:
        lines.append(f"  {p['belief']:6.1%}  {p['static_id']} in {p['room']}")
    return "\n".join(lines)
