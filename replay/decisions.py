"""Re-run every recorded planning decision with today's code on the inputs the robot had.

For each ``plan_computed`` event the log is folded up to the event before it: the scene graph, the
run's settings, the task and the robot's pose are exactly what the agent planned with. Today's
planner then plans again from there, and the two plans are compared: the room order, the order of
static objects, the objective of both under today's parameters, and — where they differ — which
inputs changed (relation values, candidates, viewpoints, α, the method, the home's map).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from objsearch.agent.catalogue import PlanComputed, decode
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.geometry import Point
from objsearch.agent.planner import wpl_terms
from objsearch.agent.policy import Method, SearchAgent, SearchConfig
from objsearch.agent.recorder import Recorder
from objsearch.agent.session import HomeContext, load_context
from objsearch.agent.state import AgentState
from objsearch.agent.stops import Stop
from objsearch.agent.strategies import (
    AGENT_MODELS,
    RelationModels,
    RelationSpec,
    RunSpec,
    split_strategy,
)
from objsearch.replay.state import ReplayState, TaskState

REL_TOLERANCE = 1e-9
VALUE_TOLERANCE = 1e-6


@dataclass(frozen=True, slots=True)
class Overrides:
    """Planner parameters to change on replay (None: keep what the run recorded)."""

    method: str | None = None
    alpha: float | None = None
    strategy: str | None = None  # a strategy's room order and planner (NAME or NAME+cover)

    def relations(self) -> RelationSpec | None:
        """The relation model to fold with instead of the run's: only a ``strategy`` override
        changes it (a counterfactual: the log folded as that strategy would have)."""
        return None if self.strategy is None else split_strategy(self.strategy)[0].relations

    def spec(self, run: RunSpec) -> RunSpec:
        """The spec to re-plan with: the run's own, with the overrides applied."""
        if self.strategy is not None:
            chosen, inspection = split_strategy(self.strategy)
            run = run.with_changes(
                strategy=chosen.name,
                method=chosen.method,
                planner=chosen.planner_name,
                relations=chosen.relations,
                params={**run.params, "inspection": inspection},
            )
        if self.method is not None:
            run = run.with_changes(method=Method(self.method), planner=self.method)
        if self.alpha is not None:
            run = run.with_changes(alpha=self.alpha)
        return run


@dataclass(frozen=True, slots=True)
class DecisionReplay:
    """One recorded plan next to today's plan from the same inputs."""

    seq: int
    task_id: str
    target: str
    room: str
    recorded_rooms: tuple[str, ...]
    replayed_rooms: tuple[str, ...]
    recorded_order: tuple[str, ...]
    replayed_order: tuple[str, ...]
    recorded_value: float  # the objective as recorded
    recorded_value_today: float  # the recorded order under today's objective and inputs
    replayed_value: float  # today's plan under today's objective
    reasons: tuple[str, ...] = field(default=())

    @property
    def same_rooms(self) -> bool:
        return self.recorded_rooms == self.replayed_rooms

    @property
    def same_order(self) -> bool:
        return self.recorded_order == self.replayed_order

    @property
    def same(self) -> bool:
        return self.same_rooms and self.same_order

    def as_dict(self) -> dict[str, Any]:
        return {
            "seq": self.seq,
            "task_id": self.task_id,
            "target": self.target,
            "room": self.room,
            "same_room_order": self.same_rooms,
            "same_object_order": self.same_order,
            "recorded_rooms": list(self.recorded_rooms),
            "replayed_rooms": list(self.replayed_rooms),
            "recorded_order": list(self.recorded_order),
            "replayed_order": list(self.replayed_order),
            "recorded_value": self.recorded_value,
            "recorded_value_today": round(self.recorded_value_today, 6),
            "replayed_value": round(self.replayed_value, 6),
            "reasons": list(self.reasons),
        }


class _NoSink:
    """Replay plans; it never acts, so nothing may be appended."""

    def append_record(self, *args: Any, **kwargs: Any) -> Any:
        raise RuntimeError("replay must not append events")


class Replayer:
    """Folds a log event by event and re-plans at every ``plan_computed``."""

    def __init__(
        self, overrides: Overrides = Overrides(), *, models: RelationModels = AGENT_MODELS
    ) -> None:
        self.overrides = overrides
        self.state = ReplayState(AgentState(counterfactual=overrides.relations(), models=models))
        self.decisions: list[DecisionReplay] = []
        self.notes: list[str] = []
        self._room_orders: dict[str, list[str]] = {}

    def feed(self, events: Iterable[Any], *, until_seq: int | None = None) -> Iterator[Any]:
        """Apply ``events`` (yielding each after it is applied), re-planning at each plan."""
        for event in events:
            if until_seq is not None and event.seq > until_seq:
                return
            if event.type == "plan_computed":
                self.decisions.append(self._replay(event))
            self.state.apply(event)
            yield event

    def _context(self, run: RunSpec) -> HomeContext:
        ctx = load_context(run.home)
        if ctx.home.digest != run.home_digest:
            note = (
                f"home {run.home!r} changed since the run (digest {run.home_digest} → "
                f"{ctx.home.digest}); plans use today's map"
            )
            if note not in self.notes:
                self.notes.append(note)
        return ctx

    def _replay(self, event: Any) -> DecisionReplay:
        st = self.state
        if st.run is None or st.task is None or st.pose is None:
            raise ObjsearchError(
                f"plan_computed at seq {event.seq} comes before its run_started/task_started; "
                "the log is incomplete"
            )
        run, task = st.run, st.task
        ctx = self._context(run)
        spec = self.overrides.spec(run)
        config = spec.config()
        agent = SearchAgent(
            ctx.navmap,
            ctx.semmap,
            ctx.vocabulary,
            st.graph,
            Recorder(_NoSink(), ()),
            config,
            spec.stop_planner(),
        )
        p = decode(event, PlanComputed)
        here = st.pose.point
        if config.method is Method.GLOBAL:
            return self._replay_global(event.seq, agent, p, here, run, config, task)
        rooms = self._room_orders.get(task.task_id)
        if rooms is None:
            start_room = ctx.navmap.room_at(task.start_pose.x, task.start_pose.y)
            rooms = agent.room_order(
                start_room, task.target, task.task_id, here=task.start_pose.point
            )
            self._room_orders = {task.task_id: rooms}
        # Exactly as the agent plans: the room's stops, plus (for planners that use them) where
        # the next room is entered and how much Rel the rooms still to come hold.
        position = task.plans_so_far
        later = rooms[position + 1 :] if rooms[position : position + 1] == [p.room] else []
        room_stops = {r: agent.stops(r, task.target) for r in (p.room, *later)}
        stops = room_stops[p.room]
        ordering = agent.plan_room(here, p.room, later, room_stops)
        replayed_order = tuple(stops[k].key for k in ordering.order)
        recorded_order = p.order
        today = _value_of(agent, config, here, stops, recorded_order)
        decision = DecisionReplay(
            seq=event.seq,
            task_id=task.task_id,
            target=task.target,
            room=p.room,
            recorded_rooms=p.room_order,
            replayed_rooms=tuple(rooms[task.plans_so_far :]),
            recorded_order=recorded_order,
            replayed_order=replayed_order,
            recorded_value=p.value,
            recorded_value_today=today,
            replayed_value=ordering.value,
        )
        if decision.same:
            return decision
        reasons = tuple(_reasons(p, run, config, stops, task)) or (
            "same inputs; today's planner prefers another order "
            f"(recorded order scores {today:.4f} today, the new one {ordering.value:.4f})",
        )
        return replace(decision, reasons=reasons)

    def _replay_global(
        self,
        seq: int,
        agent: SearchAgent,
        p: PlanComputed,
        here: Point,
        run: RunSpec,
        config: SearchConfig,
        task: TaskState,
    ) -> DecisionReplay:
        """Exactly as the agent plans a whole-home decision: over the stops of every room that
        the task has not looked at or opened yet."""
        remaining = {
            room: [
                s
                for s in agent.stops(room, task.target)
                if not any(x.id in task.searched for x in s.statics)
            ]
            for room in agent.rooms
        }
        plan = agent.plan_global(here, remaining)
        decision = DecisionReplay(
            seq=seq,
            task_id=task.task_id,
            target=task.target,
            room=p.room,
            recorded_rooms=p.room_order,
            replayed_rooms=() if plan is None else plan.rooms,
            recorded_order=p.order,
            replayed_order=() if plan is None else tuple(s.key for s in plan.order),
            recorded_value=p.value,
            # The objective is the whole plan's: a recorded room order has no score of its own.
            recorded_value_today=math.nan,
            replayed_value=math.nan if plan is None else plan.ordering.value,
        )
        if decision.same:
            return decision
        reasons = tuple(_reasons(p, run, config, remaining.get(p.room, []), task)) or (
            "same inputs; today's planner prefers another plan "
            f"(the new one scores {decision.replayed_value:.4f}, the recorded {p.value:.4f})",
        )
        return replace(decision, reasons=reasons)


def _value_of(
    agent: SearchAgent,
    config: SearchConfig,
    here: Point,
    stops: Sequence[Stop],
    order: Sequence[str],
) -> float:
    """Today's WPL for a recorded order (NaN when it names stops today's plan lacks, or when the
    planner optimises another objective, which has no score for a given order)."""
    if agent.planner.name not in ("wpl", "sdp", "rvp"):
        return math.nan
    index = {s.key: i for i, s in enumerate(stops)}
    if any(key not in index for key in order) or len(order) != len(stops):
        return math.nan
    nav = agent.navmap
    start = np.array([nav.distance(here, s.viewpoint) for s in stops], dtype=float)
    dist = np.array(
        [[nav.distance(a.viewpoint, b.viewpoint) for b in stops] for a in stops], dtype=float
    )
    rel = np.array([s.rel for s in stops], dtype=float)
    alpha = config.alpha if config.method is Method.RVP else config.effective_alpha
    return math.fsum(wpl_terms([index[k] for k in order], start, dist, rel, alpha))


def _reasons(
    plan: PlanComputed,
    run: RunSpec,
    config: SearchConfig,
    stops: Sequence[Stop],
    task: TaskState,
) -> Iterator[str]:
    if config.method is not run.method:
        yield f"method {run.method.value} → {config.method.value}"
    if config.effective_alpha != plan.alpha:
        yield f"α {plan.alpha} → {config.effective_alpha}"
    recorded = {c.static_id: c for c in plan.candidates}
    today = {s.key: s for s in stops}
    for key in sorted(recorded.keys() - today.keys()):
        yield f"candidate {key} dropped (Rel({task.target}, {recorded[key].static_class}) is 0)"
    for key in sorted(today.keys() - recorded.keys()):
        yield f"candidate {key} added (Rel({task.target}, {today[key].cls}) = {today[key].rel:.4f})"
    for key in sorted(recorded.keys() & today.keys()):
        before, now = recorded[key].rel, today[key].rel
        if abs(before - now) > REL_TOLERANCE:
            yield f"Rel({task.target}, {today[key].cls}) at {key}: {before:.4f} → {now:.4f}"
        vp = recorded[key].viewpoint
        now_vp = today[key].viewpoint
        if abs(vp[0] - now_vp.x) > 1e-6 or abs(vp[1] - now_vp.y) > 1e-6:
            yield f"viewpoint of {key}: ({vp[0]}, {vp[1]}) → ({now_vp.x}, {now_vp.y})"


def replay(
    events: Iterable[Any],
    *,
    overrides: Overrides = Overrides(),
    until_seq: int | None = None,
    models: RelationModels = AGENT_MODELS,
) -> Replayer:
    """Replay a whole stream of events; the result holds every decision and note (``models``:
    the relation models outside the agent its spec may name)."""
    replayer = Replayer(overrides, models=models)
    for _ in replayer.feed(events, until_seq=until_seq):
        pass
    return replayer


def summarise(decisions: Sequence[DecisionReplay]) -> dict[str, int]:
    return {
        "decisions": len(decisions),
        "same": sum(d.same for d in decisions),
        "different_room_order": sum(not d.same_rooms for d in decisions),
        "different_object_order": sum(not d.same_order for d in decisions),
    }
