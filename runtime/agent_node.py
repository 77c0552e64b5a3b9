"""The long-running on-robot agent: search requests in, robot commands out, every event logged
and published; and questions about its memory (``where``) answered on a thread of their own from
the live projection (:class:`~objsearch.agent.where.LiveMemory`), even during a search.

Each event is appended to the durable log first, then published on the events topic as an
``objsearch_msgs/Event`` (so the robot's bag records it); a publish that fails is reported and
the log is unaffected. A search the robot cannot finish (it stops answering, refuses, times out)
ends as ``search_failed`` with the reason and ``task_ended`` with the metres walked so far, so the
log stays a sequence of whole tasks and the next request carries on. On restart the session folds
its log and continues the task numbering and the scene graph.
"""

from __future__ import annotations

import logging
import queue
import threading
import uuid
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from objsearch.agent.catalogue import DayClock, SearchFailed, TaskEnded
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.scene_graph import UpdateMode
from objsearch.agent.session import Session, load_context
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import DEFAULT_ALPHA, DEFAULT_STRATEGY, RunSpec
from objsearch.agent.where import LiveMemory
from objsearch.events import Event
from objsearch.events.projection import EventObserver, EventView
from objsearch.runtime import messages as m
from objsearch.runtime.action import (
    STATUS_ABORTED,
    STATUS_CANCELED,
    STATUS_SUCCEEDED,
    ActionServer,
)
from objsearch.runtime.agent_interfaces import FindFeedback, find_result, where_response
from objsearch.runtime.backends import open_transport
from objsearch.runtime.config import RuntimeConfig
from objsearch.runtime.errors import RobotError, SearchCancelled
from objsearch.runtime.interfaces import FIND_OBJECT
from objsearch.runtime.interfaces import WHERE as WHERE_SRV
from objsearch.runtime.livesinks import TopicSink
from objsearch.runtime.liveview import LiveSink, LiveView
from objsearch.runtime.node import Node, Server
from objsearch.runtime.oneagent import OneAgent
from objsearch.runtime.requests import (
    FindRequest,
    WhereRequest,
    parse_find_request,
    parse_where_request,
)
from objsearch.runtime.rosworld import RobotLink, RosWorld

log = logging.getLogger("objsearch.agent")

#: Beside the log: the projection hub at the last shutdown (objsearch.events.hub): the agent's
#: state and its ``where`` memory in one snapshot file.
SNAPSHOT_DIR = "snapshots"
#: The ``where`` memory in the hub (a fold with the memory model, whatever the run's model).
WHERE = "where"
#: FindObject goals waiting for the search loop; more are rejected (as JSON requests get busy).
MAX_GOALS_QUEUED = 64


class EventPublisher:
    """An observer that publishes each appended event on the events topic."""

    def __init__(self, node: Node, config: RuntimeConfig) -> None:
        self._pub = node.publisher(config.topics.events, m.EVENT, config.qos.events)
        self.published = 0

    def apply(self, event: EventView) -> None:
        assert isinstance(event, Event)
        error = _copied(lambda: self._pub.publish(m.event(event, event.time_ns)))
        if error is None:
            self.published += 1
        else:  # the log has it; the topic is a copy
            log.warning("event %d appended but not published: %s", event.seq, error)


def _copied(step: Callable[[], None]) -> Exception | None:
    """``step()``, which copies what the log holds (the event topic, the live view, closing
    them); its error is returned, never raised."""
    try:
        step()
    except Exception as exc:  # boundary: the log is the record; a copy must not stop a search
        return exc
    return None


class GuardedLiveView:
    """The live view as an observer whose failures are reported, never raised: the log is the
    record, the view a picture of it (a full disk or a stuck viewer must not stop a search)."""

    def __init__(self, view: LiveView) -> None:
        self.view = view
        self.failures = 0

    def apply(self, event: EventView) -> None:
        exc = _copied(lambda: self.view.apply(event))
        if exc is not None:
            self.failures += 1
            if self.failures == 1 or self.failures % 1000 == 0:
                log.warning(
                    "live view: event %d not drawn (%d so far): %s", event.seq, self.failures, exc
                )


class AgentNode:
    def __init__(
        self,
        config: RuntimeConfig,
        log_dir: Path,
        *,
        strategy: str | None = None,
        alpha: float = DEFAULT_ALPHA,
        seed: int = 0,
        update_mode: UpdateMode = UpdateMode.ALL,
        live: Sequence[LiveSink] = (),
        live_topics: bool = False,
        clock: Callable[[], DayClock | None] = DayClock.local,
        perception: dict[str, Any] | None = None,
    ) -> None:
        """``live``: sinks of the live view (:mod:`objsearch.runtime.livesinks`); the node owns
        them from here on and closes them with itself. ``live_topics``: the live channels are
        also published as topics by the agent's own node (:class:`TopicSink`). ``clock``: the
        local time of day a search begins, recorded in its ``task_started`` (the host's wall
        clock: a household's hour, whatever time base the robot's stamps use — the stand-in
        robot's is simulated). ``strategy``: ``NAME`` or ``NAME+cover``; None, the product's
        default (DEFAULT_STRATEGY). ``perception``: the robot's detector as a
        :class:`~objsearch.agent.detector_model.PerceptionModel`'s params, recorded in the run
        and reasoned with (confirmation, misses); None: a perfect one."""
        self.config = config
        self.clock = clock
        self.live_sinks = tuple(live)
        transport = None
        try:
            config.check()
            self.ctx = load_context(config.home)
            transport = open_transport(config.transport)
            if live_topics:
                self.live_sinks += (TopicSink(transport),)
            self.node = Node(transport)
            # Before the log is opened or a request taken: another agent serving this robot on
            # the graph makes this one refuse (runtime/oneagent.py).
            self.one = OneAgent(self.node, config, log_dir)
            try:
                self.one.claim()
            except BaseException:
                self.one.close()
                raise
        except BaseException:
            self._close_live()
            if transport is not None:
                transport.close()
            raise
        try:
            self.events = EventPublisher(self.node, config)
            # The FindObject action's feedback, folded from the events the search appends.
            self.feedback = FindFeedback(self.ctx.home, self._most_likely)
            spec = RunSpec.of(
                self.ctx.home.name,
                self.ctx.home.digest,
                strategy or DEFAULT_STRATEGY,
                alpha=alpha,
                seed=seed,
                update_mode=update_mode,
                params={
                    "transport": config.transport.backend.value,
                    **({"perception": perception} if perception else {}),
                },
            )
            # One projection hub, restored once from one snapshot (and the log after it): the
            # agent's state and its where memory, each event folded once into each; the live
            # view reads the agent's state (no fold of its own, nothing re-read on a restart).
            log.info("restoring the agent's state from log %s", log_dir)
            self.session = Session.open(
                self.ctx,
                log_dir,
                observers=[self.events, self.feedback],
                projections=[LiveMemory.member(self.ctx.home, WHERE)],
                views=self._views,
                # A robot's runs never repeat: a new log gets a random run id, so no two robots'
                # logs share event ids (a seeded simulation derives its id instead).
                run_id=str(uuid.uuid4()),
                # A restart reads only what came after the snapshot taken at the last shutdown.
                snapshot_dir=log_dir / SNAPSHOT_DIR,
            )
            try:
                self.session.start_run(spec)
            except BaseException:
                self.session.close()
                raise
            memory = self.session.hub[WHERE]
            assert isinstance(memory, LiveMemory)
            self.memory = memory
        except BaseException:
            self.one.close()
            self.node.close()
            self._close_live()
            raise
        self._interfaces(config)

    def _interfaces(self, config: RuntimeConfig) -> None:
        """The robot's link and world, and what the agent serves: the find and where requests,
        the FindObject action and the Where service (none of them taken before :meth:`run`)."""
        self.link = RobotLink(self.node, config)
        self.world = RosWorld(self.link, self.ctx.navmap)
        t = config.topics
        self.requests = Server(
            self.node, t.find, t.find_result, config.qos.requests, parse_find_request
        )
        self.questions = Server(
            self.node, t.where, t.where_result, config.qos.requests, parse_where_request
        )
        # The typed interfaces: objsearch_msgs/action/FindObject and objsearch_msgs/srv/Where.
        self._goals: queue.Queue[tuple[bytes, FindRequest]] = queue.Queue()
        self._cancelled: set[bytes] = set()
        self._active_goal: bytes | None = None
        self._goal_lock = threading.Lock()
        self.finder = ActionServer(
            self.node,
            t.find_action,
            FIND_OBJECT,
            self._on_find_goal,
            self._on_find_cancel,
            self.world.now_ns,
        )
        self.feedback.server = self.finder
        self.node.serve(t.where_service, WHERE_SRV, self._on_where_call)
        self._stop = threading.Event()
        self._answering = threading.Thread(target=self._answer_questions, name="where", daemon=True)

    def _views(self, agent: AgentState) -> list[EventObserver]:
        """The live view, drawing from the hub's agent state (none without live sinks)."""
        if not self.live_sinks:
            return []
        view = LiveView(self.ctx, self.live_sinks, agent=agent, memory=self._memory_state)
        return [GuardedLiveView(view)]

    def _memory_state(self) -> AgentState | None:
        """The hub's where memory, for the live view's belief channels (None before it opened)."""
        session = getattr(self, "session", None)
        if session is None:
            return None
        memory = session.hub[WHERE]
        return memory.state if isinstance(memory, LiveMemory) else None

    def answer_where(self, request: WhereRequest) -> dict[str, Any]:
        """The memory's answer; ``request`` is checked field by field already (:mod:`requests`)."""
        try:
            return {"ok": True, "answer": self.memory.answer(request.target)}
        except ObjsearchError as exc:
            return {"ok": False, "error": f"where request: field 'target': {exc}"}

    def _most_likely(self, target: str) -> list[Mapping[str, Any]]:
        try:
            return list(self.memory.answer(target)["most_likely_now"])
        except ObjsearchError:
            return []

    def _on_where_call(self, request: Any, respond: Any) -> None:
        """The Where service, on a middleware thread (the memory has its own lock)."""
        target = str(request.target)
        try:
            resolved = self.ctx.vocabulary.resolve_target(target).name
        except ObjsearchError as exc:
            result: dict[str, Any] = {"ok": False, "error": f"where: target: {exc}"}
        else:
            result = self.answer_where(WhereRequest(id="service", target=resolved))
        respond(where_response(self.ctx.home, result, target))

    def _on_find_goal(self, goal_id: bytes, goal: Any) -> bool:
        """A FindObject goal, on a middleware thread: an unknown target or a full queue is
        rejected (logged); an accepted one waits for the search loop."""
        gid = uuid.UUID(bytes=goal_id)
        try:
            target = self.ctx.vocabulary.resolve_target(str(goal.target)).name
        except ObjsearchError as exc:
            log.warning("rejected FindObject goal %s: target: %s", gid, exc)
            return False
        if self._goals.qsize() >= MAX_GOALS_QUEUED:
            log.warning("rejected FindObject goal %s: %d goals are waiting", gid, MAX_GOALS_QUEUED)
            return False
        request = FindRequest(
            id=str(gid),
            target=target,
            start=str(goal.start) or None,
            scene=int(goal.scene) if int(goal.scene) >= 0 else None,
            not_before_ns=max(0, int(goal.not_before_ns)),
        )
        log.info("accepted FindObject goal %s: find %s", gid, target)
        self._goals.put((goal_id, request))
        return True

    def _on_find_cancel(self, goal_id: bytes) -> None:
        """A cancel of a goal still running: the search stops before its next robot command (a
        goal still waiting ends CANCELED when its turn comes, without a search)."""
        gid = uuid.UUID(bytes=goal_id)
        with self._goal_lock:
            self._cancelled.add(goal_id)
            if self._active_goal == goal_id:
                self.world.cancel_reason = f"cancelled by the client (FindObject goal {gid})"
                self.world.cancel.set()
        log.warning("FindObject goal %s: cancel requested by the client", gid)

    def run_goal(self, goal_id: bytes, request: FindRequest) -> None:
        """One FindObject goal: the search, its feedback, and its result (SUCCEEDED whether or
        not the target was found; CANCELED when the client cancelled it; ABORTED when the
        search could not run)."""
        gid = uuid.UUID(bytes=goal_id)
        with self._goal_lock:
            if goal_id in self._cancelled:
                self._cancelled.discard(goal_id)
                log.warning("FindObject goal %s: cancelled before it began", gid)
                self.finder.finish(goal_id, STATUS_CANCELED, self._goal_result(request, {}))
                return
            self._active_goal = goal_id
            self.world.cancel.clear()
        self.finder.executing(goal_id)
        self.feedback.begin(goal_id, request.target)
        try:
            outcome = self.handle(request)
        finally:
            self.feedback.end()
            with self._goal_lock:
                self._active_goal = None
                cancelled = goal_id in self._cancelled
                self._cancelled.discard(goal_id)
                self.world.cancel.clear()
        if outcome.get("cancelled") or (cancelled and not outcome.get("ok")):
            status = STATUS_CANCELED
        elif outcome.get("ok"):
            status = STATUS_SUCCEEDED
        else:
            status = STATUS_ABORTED
        self.finder.finish(goal_id, status, self._goal_result(request, outcome))

    def _goal_result(self, request: FindRequest, outcome: dict[str, Any]) -> Any:
        last = None
        if outcome.get("success"):
            try:
                last = self.memory.answer(request.target)["last_seen"]
            except ObjsearchError:
                last = None
        return find_result(
            target=request.target,
            task_id=str(outcome.get("task_id") or ""),
            found=bool(outcome.get("success")),
            path_length=float(outcome.get("path_length") or 0.0),
            error=str(outcome.get("error") or ""),
            last_seen=last,
            home=self.ctx.home,
            stamp_ns=self.world.now_ns(),
            diagnosis=self.node.diagnosis(),
        )

    def _serving(self) -> bool:
        return not self._stop.is_set() and self.one.rival is None

    def _answer_questions(self) -> None:
        while self._serving():
            request = self.questions.next(0.2)
            if request is None:
                continue
            try:
                result = self.answer_where(request)
            except Exception as exc:  # boundary: a bug must not leave the client waiting
                log.exception("where %s: %s", request.target, exc)
                result = {"ok": False, "error": f"where request failed: {exc}"}
            self.questions.answer(request, result)

    def handle(self, request: FindRequest) -> dict[str, Any]:
        """One search; ``request`` is checked field by field already (:mod:`requests`)."""
        try:
            target = self.ctx.vocabulary.resolve_target(request.target).name
        except ObjsearchError as exc:
            return {"ok": False, "error": f"find request: field 'target': {exc}"}
        start = request.start or "robot"
        task_id = self.session.state.tasks.next_task_id()
        try:
            self.world.fresh_pose(self.config.timeouts.robot_s, request.not_before_ns)
            result = self.session.search(
                self.world, target, start, scene=request.scene, clock=self.clock()
            )
        except RobotError as exc:
            cancelled = isinstance(exc, SearchCancelled)
            error = str(exc)
            # What the graph shows wrong goes into the answer (and the log), not only the log's
            # warnings: a publisher of another type, a QoS mismatch, malformed messages.
            diagnosis = [] if cancelled else self.node.diagnosis()
            if diagnosis:
                error += "; on the graph: " + "; ".join(diagnosis)
            if cancelled:
                log.warning("%s: search for %s stopped: %s", task_id, target, error)
            else:
                log.error("%s: search for %s failed: %s", task_id, target, error)
            open_task = self.session.state.tasks.open
            metres = 0.0
            if open_task is not None and open_task.task_id == task_id:
                metres = open_task.metres
                reason = f"cancelled: {error}" if cancelled else f"robot: {error}"
                self._fail_task(task_id, target, reason, metres)
            failed = {"ok": False, "target": target, "task_id": task_id, "error": error}
            if cancelled:
                failed.update(cancelled=True, path_length=round(metres, 4))
            return failed
        return {
            "ok": True,
            "target": target,
            "task_id": result.task_id,
            "success": result.success,
            "path_length": result.path_length,
            "found": result.found_instance,
            "plans": [[room, list(order)] for room, order in result.plans],
        }

    def _fail_task(self, task_id: str, target: str, reason: str, metres: float) -> None:
        now = self.world.now_ns()
        with self.session.log.batch():
            recorder = self.session.recorder
            recorder.emit(SearchFailed(reason=reason), time_ns=now, task_id=task_id)
            recorder.emit(
                TaskEnded(target=target, success=False, path_length=round(metres, 4)),
                time_ns=now,
                task_id=task_id,
            )

    def stop(self) -> None:
        self._stop.set()

    def run(self) -> int:
        log.info(
            "agent up: %s, log %s", self.config.transport.backend.value, self.session.log.directory
        )
        self._answering.start()
        try:
            # Another agent of this robot met while serving, whose claim came first: this one
            # stops after the search it is in (runtime/oneagent.py).
            while self._serving():
                request = self.requests.next(0.1)
                if request is not None:
                    self.requests.answer(request, self.handle(request))
                try:
                    goal_id, goal = self._goals.get(timeout=0.1)
                except queue.Empty:
                    continue
                self.run_goal(goal_id, goal)
        finally:
            self._stop.set()
            self._answering.join()
            self.close()
        if self.one.rival is not None:
            raise self.one.refusal()
        return 0

    def close(self) -> None:
        try:
            self.session.close()  # the hub's one snapshot: the agent's state and its memory
            self.one.close()
            self.node.close()
        finally:
            self._close_live()

    def _close_live(self) -> None:
        for sink in self.live_sinks:
            exc = _copied(sink.close)
            if exc is not None:  # the others still get closed
                log.error("live view: %s", exc)
