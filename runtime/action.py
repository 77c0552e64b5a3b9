"""ROS 2 actions over the transport seam, as rcl_action lays them out.

An action ``/navigate_to_pose`` is three services and two topics under ``/navigate_to_pose/
_action/``: ``send_goal``, ``get_result`` (answered when the goal ends), ``cancel_goal``
(``action_msgs/srv/CancelGoal``), ``feedback`` and ``status`` (``action_msgs/GoalStatusArray``,
latched). Goal ids are 16-byte UUIDs; a client may send the same goal again (a lost reply) and
gets the first answer, as the server keys its goals by id.
"""

from __future__ import annotations

import threading
import uuid
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from objsearch.ros.qos import ACTION_STATUS, DEFAULT
from objsearch.runtime import messages as m
from objsearch.runtime.interfaces import CANCEL_GOAL
from objsearch.runtime.node import Node

# action_msgs/msg/GoalStatus
STATUS_UNKNOWN = 0
STATUS_ACCEPTED = 1
STATUS_EXECUTING = 2
STATUS_CANCELING = 3
STATUS_SUCCEEDED = 4
STATUS_CANCELED = 5
STATUS_ABORTED = 6
STATUS_NAMES = {
    0: "unknown",
    1: "accepted",
    2: "executing",
    3: "canceling",
    4: "succeeded",
    5: "canceled",
    6: "aborted",
}
TERMINAL = {STATUS_SUCCEEDED, STATUS_CANCELED, STATUS_ABORTED}

#: Goals an :class:`ActionServer` remembers; beyond this the oldest finished (or rejected) ones
#: are forgotten (rcl_action drops results after a timeout too), so memory stays bounded.
MAX_GOALS = 256

# action_msgs/srv/CancelGoal return codes
CANCEL_OK = 0
CANCEL_REJECTED = 1
CANCEL_UNKNOWN_GOAL = 2
CANCEL_TERMINATED = 3


def topics(name: str) -> dict[str, str]:
    base = "/" + name.strip("/") + "/_action/"
    return {k: base + k for k in ("send_goal", "get_result", "cancel_goal", "feedback", "status")}


def new_goal_id() -> bytes:
    return uuid.uuid4().bytes


def _uuid(goal_id: bytes) -> Any:
    return m.types()["unique_identifier_msgs/msg/UUID"](
        uuid=np.frombuffer(goal_id, dtype=np.uint8).copy()
    )


def _goal_info(goal_id: bytes, stamp_ns: int) -> Any:
    return m.types()["action_msgs/msg/GoalInfo"](goal_id=_uuid(goal_id), stamp=m.stamp(stamp_ns))


@dataclass(frozen=True, slots=True)
class Accepted:
    accepted: bool
    stamp_ns: int


@dataclass(frozen=True, slots=True)
class Outcome:
    status: int
    result: Any


class ActionClient:
    def __init__(self, node: Node, name: str, action: str) -> None:
        self.name = name
        self.action = action
        t = topics(name)
        self._send = node.client(t["send_goal"], f"{action}_SendGoal")
        self._result = node.client(t["get_result"], f"{action}_GetResult")
        self._cancel = node.client(t["cancel_goal"], CANCEL_GOAL)

    def send_goal(self, goal_id: bytes, goal: Any, timeout_s: float) -> Accepted | None:
        request = m.types()[f"{self.action}_SendGoal_Request"](goal_id=_uuid(goal_id), goal=goal)
        response = self._send.call(request, timeout_s)
        if response is None:
            return None
        return Accepted(bool(response.accepted), m.stamp_ns(response))

    def get_result(self, goal_id: bytes, timeout_s: float) -> Outcome | None:
        request = m.types()[f"{self.action}_GetResult_Request"](goal_id=_uuid(goal_id))
        response = self._result.call(request, timeout_s)
        return None if response is None else Outcome(int(response.status), response.result)

    def why_unanswered(self) -> str | None:
        """What the transport can tell about a send_goal nobody answered (None: nothing)."""
        why = getattr(self._send.transport_client, "why_unanswered", None)
        return None if why is None else why()

    def cancel(self, goal_id: bytes, timeout_s: float) -> int | None:
        """The CancelGoal return code, or None without an answer."""
        request = m.types()[f"{CANCEL_GOAL}_Request"](goal_info=_goal_info(goal_id, 0))
        response = self._cancel.call(request, timeout_s)
        return None if response is None else int(response.return_code)


@dataclass
class _Goal:
    goal_id: bytes
    accepted: bool
    stamp_ns: int
    status: int = STATUS_ACCEPTED
    result: Any = None
    waiting: list[Callable[[Any], None]] = field(default_factory=list)


#: Decides on a new goal: ``(goal_id, goal) -> accept?``; None leaves send_goal unanswered.
GoalCallback = Callable[[bytes, Any], bool | None]


class ActionServer:
    """Goals are accepted (or not) by ``on_goal``; whoever executes them calls :meth:`finish`.

    ``on_cancel(goal_id)`` is told of a cancel request for a goal still running; the goal is
    CANCELING until its executor finishes it (as CANCELED, normally)."""

    def __init__(
        self,
        node: Node,
        name: str,
        action: str,
        on_goal: GoalCallback,
        on_cancel: Callable[[bytes], None],
        clock: Callable[[], int],
    ) -> None:
        self.action = action
        self._on_goal = on_goal
        self._on_cancel = on_cancel
        self._clock = clock
        self._goals: dict[bytes, _Goal] = {}
        self._lock = threading.RLock()
        self.cancel_requests: deque[bytes] = deque(maxlen=MAX_GOALS)  # the latest, for tests
        t = topics(name)
        self._status = node.publisher(t["status"], m.GOAL_STATUS_ARRAY, ACTION_STATUS)
        self._feedback = node.publisher(t["feedback"], f"{action}_FeedbackMessage", DEFAULT)
        node.serve(t["send_goal"], f"{action}_SendGoal", self._handle_send_goal)
        node.serve(t["get_result"], f"{action}_GetResult", self._handle_get_result)
        node.serve(t["cancel_goal"], CANCEL_GOAL, self._handle_cancel)

    def _empty_result(self) -> Any:
        return m.default(f"{self.action}_Result")

    def _send_goal_response(self, goal: _Goal) -> Any:
        return m.types()[f"{self.action}_SendGoal_Response"](
            accepted=goal.accepted, stamp=m.stamp(goal.stamp_ns)
        )

    def _handle_send_goal(self, request: Any, respond: Callable[[Any], None]) -> None:
        goal_id = bytes(request.goal_id.uuid)
        with self._lock:
            known = self._goals.get(goal_id)
            if known is None:
                decision = self._on_goal(goal_id, request.goal)
                if decision is None:
                    return  # a fault: the robot never answers
                known = _Goal(goal_id, decision, self._clock())
                if not decision:
                    known.status = STATUS_UNKNOWN
                self._goals[goal_id] = known
                self._forget_old_goals()
                self._publish_status()
            respond(self._send_goal_response(known))

    def _forget_old_goals(self) -> None:
        excess = len(self._goals) - MAX_GOALS
        if excess > 0:
            done = [gid for gid, g in self._goals.items() if not g.accepted or g.status in TERMINAL]
            for gid in done[:excess]:
                del self._goals[gid]

    def _handle_get_result(self, request: Any, respond: Callable[[Any], None]) -> None:
        goal_id = bytes(request.goal_id.uuid)
        response = m.types()[f"{self.action}_GetResult_Response"]
        with self._lock:
            goal = self._goals.get(goal_id)
            if goal is None or not goal.accepted:
                respond(response(status=STATUS_UNKNOWN, result=self._empty_result()))
            elif goal.status in TERMINAL:
                respond(response(status=goal.status, result=goal.result))
            else:
                goal.waiting.append(respond)

    def _handle_cancel(self, request: Any, respond: Callable[[Any], None]) -> None:
        goal_id = bytes(request.goal_info.goal_id.uuid)
        response = m.types()[f"{CANCEL_GOAL}_Response"]
        with self._lock:
            self.cancel_requests.append(goal_id)
            goal = self._goals.get(goal_id)
            if goal is None or not goal.accepted:
                respond(response(return_code=CANCEL_UNKNOWN_GOAL, goals_canceling=[]))
                return
            if goal.status in TERMINAL:
                respond(response(return_code=CANCEL_TERMINATED, goals_canceling=[]))
                return
            goal.status = STATUS_CANCELING
            self._publish_status()
            respond(
                response(
                    return_code=CANCEL_OK,
                    goals_canceling=[_goal_info(goal_id, goal.stamp_ns)],
                )
            )
        self._on_cancel(goal_id)

    def finish(self, goal_id: bytes, status: int, result: Any = None) -> None:
        response = m.types()[f"{self.action}_GetResult_Response"]
        with self._lock:
            goal = self._goals[goal_id]
            goal.status = status
            goal.result = self._empty_result() if result is None else result
            waiting, goal.waiting = goal.waiting, []
            self._publish_status()
            for respond in waiting:
                respond(response(status=goal.status, result=goal.result))

    def executing(self, goal_id: bytes) -> None:
        with self._lock:
            self._goals[goal_id].status = STATUS_EXECUTING
            self._publish_status()

    def publish_feedback(self, goal_id: bytes, feedback: Any) -> None:
        msg = m.types()[f"{self.action}_FeedbackMessage"](goal_id=_uuid(goal_id), feedback=feedback)
        self._feedback.publish(msg)

    def _publish_status(self) -> None:
        t = m.types()
        self._status.publish(
            t[m.GOAL_STATUS_ARRAY](
                status_list=[
                    t["action_msgs/msg/GoalStatus"](
                        goal_info=_goal_info(g.goal_id, g.stamp_ns), status=g.status
                    )
                    for g in self._goals.values()
                    if g.accepted
                ][-32:]  # the recent goals (rcl_action drops results after a timeout too)
            )
        )
