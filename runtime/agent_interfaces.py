"""The agent's typed ROS 2 interfaces: ``objsearch_msgs/action/FindObject`` and
``objsearch_msgs/srv/Where``, as a ROS user asks them (``ros2 action send_goal``, ``ros2 service
call``), beside the JSON topics kept for clients without ROS 2.

The messages are built from what the agent already computes: a Where answer and the found
object's place are the ``where`` memory's answer (:mod:`objsearch.agent.where`: places, rooms,
last seen and its evidence age), and the action's feedback is folded from the events the search
appends (plan, moves), so the typed answers say what the log says.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable, Mapping
from typing import Any

from objsearch.agent.home import Home
from objsearch.events.projection import EventView
from objsearch.runtime import messages as m
from objsearch.runtime.action import ActionServer
from objsearch.runtime.interfaces import FIND_OBJECT, WHERE

PLACE = "objsearch_msgs/msg/PlaceProbability"
ROOM = "objsearch_msgs/msg/RoomProbability"
SIGHTING = "objsearch_msgs/msg/Sighting"


def point(x: float, y: float, z: float = 0.0) -> Any:
    return m.types()["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=float(z))


def _static_point(home: Home, static_id: str) -> Any:
    static = home.statics.get(static_id)
    return point(0.0, 0.0) if static is None else point(*static.box.center)


def places(home: Home, entries: list[Mapping[str, Any]]) -> list[Any]:
    """``most_likely_now`` entries of a where answer as ``PlaceProbability`` messages."""
    cls = m.types()[PLACE]
    return [
        cls(
            static_id=str(p["static_id"]),
            static_class=str(p["static_class"]),
            room=str(p["room"]),
            probability=float(p["probability"]),
            position=_static_point(home, str(p["static_id"])),
        )
        for p in entries
    ]


def rooms(entries: list[Mapping[str, Any]]) -> list[Any]:
    cls = m.types()[ROOM]
    return [cls(room=str(r["room"]), probability=float(r["probability"])) for r in entries]


def sighting(last: Mapping[str, Any] | None) -> Any:
    """A where answer's ``last_seen`` (None: never seen). Its evidence age is the answer's
    ``age_s`` where the memory gives one, else -1 (not known)."""
    cls = m.types()[SIGHTING]
    if last is None:
        return cls(
            seen=False,
            static_id="",
            static_class="",
            at=False,
            has_position=False,
            position=point(0.0, 0.0),
            room="",
            task_id="",
            stamp=m.stamp(0),
            age_s=-1.0,
            scene=-1,
        )
    position = last.get("position")
    age = last.get("age_s")
    return cls(
        seen=True,
        static_id=str(last.get("static_id") or ""),
        static_class=str(last.get("static_class") or ""),
        at=bool(last.get("at")),
        has_position=position is not None,
        position=point(*position) if position is not None else point(0.0, 0.0),
        room=str(last.get("room") or ""),
        task_id=str(last.get("task_id") or ""),
        stamp=m.stamp(int(last.get("time_ns") or 0)),
        age_s=-1.0 if age is None else float(age),
        scene=-1 if last.get("scene") is None else int(last["scene"]),
    )


def where_response(home: Home, result: Mapping[str, Any], target: str) -> Any:
    """The Where service's response from the agent's where result (``{ok, answer | error}``)."""
    cls = m.types()[f"{WHERE}_Response"]
    answer = result.get("answer")
    if not result.get("ok") or not isinstance(answer, Mapping):
        return cls(
            ok=False,
            error=str(result.get("error") or "no answer"),
            target=target,
            tasks=0,
            places=[],
            rooms=[],
            elsewhere=0.0,
            last_seen=sighting(None),
            usually="",
            answer_json="",
        )
    usually = answer.get("usually")
    return cls(
        ok=True,
        error="",
        target=str(answer["target"]),
        tasks=int(answer.get("tasks") or 0),
        places=places(home, list(answer.get("most_likely_now") or [])),
        rooms=rooms(list(answer.get("rooms") or [])),
        elsewhere=float(answer.get("elsewhere") or 0.0),
        last_seen=sighting(answer.get("last_seen")),
        usually=str(usually["static_id"]) if isinstance(usually, Mapping) else "",
        answer_json=json.dumps(answer, sort_keys=True, separators=(",", ":")),
    )


def find_result(
    *,
    target: str,
    task_id: str,
    found: bool,
    path_length: float,
    error: str,
    last_seen: Mapping[str, Any] | None,
    home: Home,
    stamp_ns: int,
    diagnosis: list[str],
) -> Any:
    """The action's result. Where it was found is the memory's latest sighting of the target,
    taken only when it belongs to this search."""
    t = m.types()
    place = room = ""
    pose = m.types()["geometry_msgs/msg/PoseStamped"](
        header=m.header(stamp_ns),
        pose=t["geometry_msgs/msg/Pose"](
            position=point(0.0, 0.0),
            orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        ),
    )
    if found and last_seen is not None and last_seen.get("task_id") == task_id:
        room = str(last_seen.get("room") or "")
        if last_seen.get("at"):
            place = str(last_seen.get("static_id") or "")
        position = last_seen.get("position")
        if position is not None:
            pose.pose.position = point(*position)
        elif place:
            pose.pose.position = _static_point(home, place)
        pose.header = m.header(int(last_seen.get("time_ns") or stamp_ns))
    return t[f"{FIND_OBJECT}_Result"](
        found=found,
        target=target,
        task_id=task_id,
        place=place,
        room=room,
        pose=pose,
        path_length=float(path_length),
        error=error,
        diagnosis=list(diagnosis),
    )


class FindFeedback:
    """An observer of the agent's events that, while a FindObject goal runs, publishes its
    feedback after each plan and each move: the room, the next stop, the path so far and the
    target's most likely places (``belief()``, the where memory's)."""

    def __init__(self, home: Home, belief: Callable[[str], list[Mapping[str, Any]]]) -> None:
        self.home = home
        self._belief = belief
        self.server: ActionServer | None = None
        self._lock = threading.Lock()
        self._goal: bytes | None = None
        self._target = ""
        self._reset()
        self.published = 0

    def _reset(self) -> None:
        self._task_id = ""
        self._room = ""
        self._order: list[str] = []
        self._viewed: set[str] = set()
        self._metres = 0.0
        self._path: list[tuple[float, float]] = []
        self._places: list[Mapping[str, Any]] = []

    def begin(self, goal_id: bytes, target: str) -> None:
        with self._lock:
            self._goal, self._target = goal_id, target
            self._reset()

    def end(self) -> None:
        with self._lock:
            self._goal = None

    def apply(self, event: EventView) -> None:
        with self._lock:
            if self._goal is None:
                return
            p = event.payload
            kind = event.type
            if kind == "task_started":
                self._reset()
                self._task_id = event.task_id or ""
                pose = p.get("pose") or {}
                self._path.append((float(pose.get("x", 0.0)), float(pose.get("y", 0.0))))
                return
            if kind == "view_taken" and p.get("static_id"):
                self._viewed.add(str(p["static_id"]))
                return
            if kind == "plan_computed":
                self._room = str(p.get("room", ""))
                self._order = [str(s) for s in p.get("order", ())]
                self._viewed.clear()
                self._places = self._belief(self._target)
            elif kind == "moved":
                self._metres += float(p.get("metres", 0.0))
                end = p.get("end") or {}
                self._path.append((float(end.get("x", 0.0)), float(end.get("y", 0.0))))
            else:
                return
            self._publish()

    def _publish(self) -> None:
        if self.server is None or self._goal is None:
            return
        upcoming = [s for s in self._order if s not in self._viewed]
        next_stop = upcoming[0] if upcoming else ""
        feedback = m.types()[f"{FIND_OBJECT}_Feedback"](
            task_id=self._task_id,
            room=self._room,
            next_stop=next_stop,
            next_stop_position=_static_point(self.home, next_stop) if next_stop else point(0, 0),
            path_length=round(self._metres, 4),
            path=[point(x, y) for x, y in self._path],
            belief=places(self.home, self._places),
        )
        self.server.publish_feedback(self._goal, feedback)
        self.published += 1
