"""The search policy (paper §5.1): rooms in order, static objects in planned order, look or open.

Every step is appended to the event log through a :class:`~objsearch.agent.recorder.Recorder`,
which also feeds the projections, so the scene graph the next plan uses is always the fold of what
was written. The agent plans; each search's acting is a :class:`~objsearch.agent.task.SearchTask`
(moves, views, confirming looks), its stops and their rules are ``agent/stops.py``.
"""

from __future__ import annotations

import enum
import functools
import math
import random
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypedDict, Unpack

import numpy as np

from objsearch.agent.belief import ELSEWHERE_PRIOR, MISS, TYPICAL_MASK_PX
from objsearch.agent.camera_frames import CAMERA_HEIGHT_M
from objsearch.agent.catalogue import (
    Candidate,
    DayClock,
    PlanComputed,
    SearchFailed,
    TargetDetected,
    TargetFound,
    TaskEnded,
    TaskStarted,
)
from objsearch.agent.categories import Category, Vocabulary
from objsearch.agent.detector_model import PerceptionModel, class_sizes, expected_mask_px
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.event_values import planar, xy, xyz
from objsearch.agent.geometry import Point, heading
from objsearch.agent.navmap import DistanceTable, NavigationMap
from objsearch.agent.planner import (
    Ordering,
    PlanProblem,
    RelationOrderPlanner,
    StopPlanner,
    WplPlanner,
    epl_plan,
    epl_probabilities,
)
from objsearch.agent.recorder import Recorder
from objsearch.agent.relations import RelationModel, instance_value
from objsearch.agent.results import Found, SearchResult
from objsearch.agent.room_order import expected_cost_order
from objsearch.agent.semmap import MappedStatic, SemanticMap
from objsearch.agent.stops import Stop, static_point, stop_value
from objsearch.agent.task import SearchTask
from objsearch.agent.world import World

INSPECTIONS = ("single", "cover")
#: The whole-home planner's exact size: its DP holds 2^K · K states, K = 12 keeps a decision within
#: the 50 ms target on the largest home (benchmarks/decisions.py); beyond, a bounded approximation.
GLOBAL_EXACT_STOPS = 12
#: Revisits (docs/perception.md): with a detector whose misses are independent from look to look,
#: a search that found nothing searches the stops again, each weighted by its value times the
#: per-look miss to the power of its inspections so far, until the mass left at the stops is below
#: ``REVISIT_EPSILON`` of what it was (1 − the 99.5 % success target), or after
#: ``REVISIT_PASSES`` passes in all (the budget).
REVISIT_EPSILON = 0.005
REVISIT_PASSES = 8


class Method(enum.Enum):
    WPL = "wpl"  # the paper's method: rooms by Σ Rel, objects by minimum WPL (α = 10)
    RVP = "rvp"  # relation value priority: rooms by Σ Rel, objects by Rel
    SDP = "sdp"  # shortest distance priority: random rooms, objects by WPL with α = 0
    ECOST = "ecost"  # ours: rooms by minimum expected cost over all orders (agent/room_order.py)
    #: ours: one plan over every stop of the home, rooms not searched whole (SearchAgent.plan_global)
    GLOBAL = "global"


@dataclass(frozen=True)
class SearchConfig:
    method: Method = Method.WPL
    alpha: float = 10.0
    support_radius: float = 0.5  # an object this close to a static's box is "at" it (Eq. 4)
    seed: int = 0
    #: "single": each static from its N_s (the paper); "cover": when that finds nothing, a second
    #: pass looks at long statics from the viewpoints nearest each stretch (:func:`cover_points`).
    inspection: str = "single"
    #: The detector the robot sees with (what a detection's score and a miss mean); perfect:
    #: every detection of the target ends the search, as the paper's simulator had it.
    perception: PerceptionModel = field(default_factory=PerceptionModel)

    @property
    def effective_alpha(self) -> float:
        return 0.0 if self.method is Method.SDP else self.alpha

    def default_planner(self) -> StopPlanner:
        """The paper's planner for ``method``: RVP, or WPL (SDP: α = 0)."""
        if self.method is Method.RVP:
            return RelationOrderPlanner(alpha=self.alpha)
        return WplPlanner(alpha=self.effective_alpha, name=self.method.value)


@dataclass(frozen=True, slots=True)
class GlobalPlan:
    """One decision of the whole-home planner: where to search next, and the plan behind it.

    ``room``: the room of the plan's first stop; ``order``: that room's remaining stops in the
    plan's order; the first ``segment`` of them are searched before the plan leaves the room (and
    is made anew from there); ``rooms``: the rooms in the order the plan enters them (a room may
    come back); ``ordering``: the terms of the whole plan over every remaining stop.
    """

    room: str
    order: tuple[Stop, ...]
    segment: int
    rooms: tuple[str, ...]
    ordering: Ordering


class SearchOptions(TypedDict, total=False):
    """A search's optional keywords, recorded in its ``task_started`` (one definition for the
    agent's ``search`` and the session's, which passes them on)."""

    scene: int | None  # the schedule's scene the world was built from
    clock: DayClock | None  # the local time of day the search begins


class SearchAgent:
    """Runs one search task after another in a world, recording every step."""

    def __init__(
        self,
        navmap: NavigationMap,
        semmap: SemanticMap,
        vocabulary: Vocabulary,
        graph: RelationModel,
        recorder: Recorder,
        config: SearchConfig,
        planner: StopPlanner | None = None,
        next_task_id: Callable[[], str] | None = None,
        data: Path | None = None,
    ) -> None:
        self.navmap = navmap
        self.semmap = semmap
        self.vocabulary = vocabulary
        self.graph = graph
        self.recorder = recorder
        self.config = config
        #: Orders the stops of a room; the paper's planner for ``config.method`` unless plugged in.
        self.planner = planner or config.default_planner()
        self.rooms = tuple(navmap.doors)
        #: Task ids come from the log's task ledger (objsearch.agent.state), never from a counter
        #: in the relation model: a crashed task must not hand its id to the next one.
        self._next_task_id = next_task_id
        self._recall_cache: dict[tuple[str, str], tuple[float, ...]] = {}
        #: The data folder of the class sizes (the run's; None: ``datapaths.data_dir()``).
        self.data = data
        #: How many movable classes there are: a false report's share of the detector's false
        #: positives (``TaskOdds.sighting_odds``).
        self.movable_classes = len(vocabulary.names(Category.SEMI_DYNAMIC))

    # -- what a look says under a modelled detector ---------------------------------------------

    def stop_miss(self, target: str, stop: Stop) -> float:
        """P(one inspection of ``stop`` misses ``target`` when it is there): the belief's own
        ``MISS`` (occlusion, range) and the detector's miss for the mask the target is expected
        to show from the stop's viewpoint — its class's typical size
        (:func:`~objsearch.agent.detector_model.class_sizes`) at each static's distance and
        angle (:func:`~objsearch.agent.detector_model.expected_mask_px`), the recall averaged
        over the stop's statics; a class of unknown size shows a typical mask."""
        recalls = self._recalls(target, stop)
        return 1.0 - (1.0 - MISS) * math.fsum(recalls) / len(recalls)

    def stop_miss_after(self, target: str, stop: Stop, looks: int) -> float:
        """P(``looks`` inspections of ``stop`` all miss ``target`` when it is there), by the
        run's ``stop_misses`` (:data:`~objsearch.agent.detector_model.STOP_MISSES`): ``pooled``,
        :meth:`stop_miss` to the power of ``looks``; ``per-static``, each static's own miss to
        that power, averaged (the target at one of them, equally likely)."""
        if looks <= 0:
            return 1.0
        if self.config.perception.stop_misses == "pooled":
            return self.stop_miss(target, stop) ** looks
        recalls = self._recalls(target, stop)
        return math.fsum((1.0 - (1.0 - MISS) * r) ** looks for r in recalls) / len(recalls)

    def _recalls(self, target: str, stop: Stop) -> tuple[float, ...]:
        """The detector's recall of ``target`` at each of ``stop``'s statics (:meth:`stop_miss`)."""
        key = (target, stop.key)
        recalls = self._recall_cache.get(key)
        if recalls is None:
            model = self.config.perception
            size = class_sizes(self.data).get(target)
            vp = stop.viewpoint
            found = []
            for s in stop.statics:
                x, y, z = static_point(s)
                across = math.hypot(x - vp.x, y - vp.y)
                mask = TYPICAL_MASK_PX
                if size is not None:
                    mask = expected_mask_px(
                        size,
                        math.hypot(across, CAMERA_HEIGHT_M - z),
                        max(0.0, math.atan2(CAMERA_HEIGHT_M - z, across)),
                    )
                found.append(model.recall(mask))
            recalls = self._recall_cache[key] = tuple(found)
        return recalls

    def place_probabilities(self, d: str) -> tuple[dict[str, float], float]:
        """P(d at each mapped static) and P(d elsewhere) by the relation model: values that sum
        to at most 1 over the home's statics are a distribution (the belief, the oracles), the
        rest of 1 is elsewhere; others (the scene graph, the memory: independent chances) are
        normalised, leaving ``ELSEWHERE_PRIOR`` for elsewhere."""
        values = {s.id: instance_value(self.graph, d, s.id, s.cls) for s in self.semmap.statics}
        total = math.fsum(values.values())
        if total <= 1.0 + 1e-9:
            return values, max(0.0, 1.0 - total)
        scale = (1.0 - ELSEWHERE_PRIOR) / total
        return {k: v * scale for k, v in values.items()}, ELSEWHERE_PRIOR

    # -- planning -----------------------------------------------------------------------------

    @functools.cached_property
    def stop_table(self) -> DistanceTable:
        """Metres between the viewpoints of every mapped static: what a plan's distances are
        taken from. Built once per agent (a session builds one per run, so per map id;
        :meth:`~objsearch.agent.session.Session.start_run` builds it before the first search)."""
        return DistanceTable(self.navmap, [s.viewpoint for s in self.semmap.statics])

    def stops(self, room: str, target: str) -> list[Stop]:
        """Static objects related to the target (value > 0), grouped by (viewpoint, class).

        A stop's value is Rel(target, class), or, for a model with per-instance values
        (:class:`~objsearch.agent.relations.InstanceRelations`), the sum over its instances
        (capped at 1)."""
        groups: dict[tuple[Point, str], list[MappedStatic]] = {}
        for s in self.semmap.in_room(room):
            if instance_value(self.graph, target, s.id, s.cls) > 0:
                groups.setdefault((s.viewpoint, s.cls), []).append(s)
        stops = [
            Stop(tuple(sorted(g, key=lambda s: s.id)), stop_value(self.graph, target, g))
            for g in groups.values()
        ]
        return sorted(stops, key=lambda st: st.key)

    def room_relation(self, room: str, target: str) -> float:
        """Rel(target, R): the sum of Rel over the static classes present in the room."""
        classes = {s.cls for s in self.semmap.in_room(room)}
        return math.fsum(self.graph.rel(target, c) for c in sorted(classes))

    def room_order(
        self, start_room: str, target: str, task_id: str, *, here: Point | None = None
    ) -> list[str]:
        """Rooms in search order; ``here`` (the start pose) matters to the expected-cost order."""
        if self.config.method is Method.ECOST:
            return expected_cost_order(
                self.rooms,
                start_room,
                here or self.navmap.doors[start_room],
                self.navmap.doors,
                {r: [(s.viewpoint, s.rel) for s in self.stops(r, target)] for r in self.rooms},
                self.navmap.distance,
            )
        rest = [r for r in self.rooms if r != start_room]
        if self.config.method is Method.SDP:
            random.Random(f"{self.config.seed}:{task_id}").shuffle(rest)
        else:
            rest.sort(key=lambda r: (-self.room_relation(r, target), self.rooms.index(r)))
        return [start_room, *rest]

    def order_stops(
        self,
        here: Point,
        stops: Sequence[Stop],
        *,
        next_entry: Point | None = None,
        rest_mass: float = 0.0,
    ) -> Ordering:
        """Order a room's stops with the planner; ``next_entry`` is where the next room to search
        is entered and ``rest_mass`` the summed Rel of the candidates in the rooms still to come."""
        n = len(stops)
        start = np.array([self.navmap.distance(here, s.viewpoint) for s in stops], dtype=float)
        dist = np.zeros((n, n))
        for i, a in enumerate(stops):
            for j, b in enumerate(stops):
                if i != j:
                    dist[i, j] = self.navmap.distance(a.viewpoint, b.viewpoint)
        rel = np.array([s.rel for s in stops], dtype=float)
        to_exit = (
            None
            if next_entry is None
            else np.array([self.navmap.distance(s.viewpoint, next_entry) for s in stops])
        )
        return self.planner.plan(PlanProblem(start, dist, rel, to_exit, rest_mass))

    def plan_room(
        self,
        here: Point,
        room: str,
        later: Sequence[str],
        room_stops: Mapping[str, Sequence[Stop]],
    ) -> Ordering:
        """Order ``room``'s stops as a search does: from ``here``, with the entry of the next room
        to search (the first of ``later``) and the Rel its candidates and the rest still hold.
        ``room_stops`` maps ``room`` and every room of ``later`` to its :meth:`stops`. The one
        statement of the planner's inputs: the search and replay's re-planning both call it."""
        return self.order_stops(
            here,
            room_stops[room],
            next_entry=self.navmap.doors[later[0]] if later else None,
            rest_mass=math.fsum(s.rel for r in later for s in room_stops[r]),
        )

    def plan_global(
        self, here: Point, remaining: Mapping[str, Sequence[Stop]]
    ) -> GlobalPlan | None:
        """One plan over every remaining stop of the home (``remaining``: per room, the stops not
        searched yet in this task): minimum expected metres to discovery, P(stop) ∝ its value, rooms
        entered as often as the plan likes. Exact up to ``GLOBAL_EXACT_STOPS`` stops, else the
        bounded approximation of :func:`~objsearch.agent.planner.epl_plan`. None when nothing is
        left. The one statement of this decision: the search and replay's re-planning call it."""
        flat = [(room, stop) for room in self.rooms for stop in remaining.get(room, ())]
        if not flat:
            return None
        points = [s.viewpoint for _, s in flat]
        start = self.navmap.distances(here, points)
        dist = self.stop_table.between(points)
        prob = epl_probabilities(np.array([s.rel for _, s in flat], dtype=float), 0.0)
        ordering = epl_plan(start, dist, prob, None, GLOBAL_EXACT_STOPS)
        rooms: list[str] = []
        for k in ordering.order:
            if not rooms or rooms[-1] != flat[k][0]:
                rooms.append(flat[k][0])
        first = rooms[0]
        order = tuple(flat[k][1] for k in ordering.order if flat[k][0] == first)
        segment = 0
        for k in ordering.order:
            if flat[k][0] != first:
                break
            segment += 1
        return GlobalPlan(first, order, segment, tuple(rooms), ordering)

    # -- acting -------------------------------------------------------------------------------

    def search(
        self, world: World, target: str, start: str, **options: Unpack[SearchOptions]
    ) -> SearchResult:
        scene, clock = options.get("scene"), options.get("clock")
        if self._next_task_id is None:
            raise ObjsearchError("this agent only plans (replay); it was given no task numbering")
        task_id = self._next_task_id()
        run = SearchTask(self, world, task_id, target)
        result = SearchResult(
            task_id=task_id, target=target, start=start, success=False, path_length=0.0
        )
        pose = world.pose()
        result.route.append(pose.point)
        run.emit(
            TaskStarted(target=target, start=start, pose=planar(pose), scene=scene, clock=clock)
        )
        start_room = self.navmap.room_at(pose.x, pose.y)
        if self.config.method is Method.GLOBAL:
            rooms = list(self.rooms)
        else:
            rooms = self.room_order(start_room, target, task_id, here=pose.point)
        room_stops = {room: self.stops(room, target) for room in rooms}
        run.stop_of = {
            st.id: stop for stops in room_stops.values() for stop in stops for st in stop.statics
        }
        found = self._pass(run, result, rooms, room_stops)
        reason = f"{target} not found in any room"
        if found is None and not self.config.perception.perfect:
            found, reason = self._revisit(run, result, rooms, room_stops)
        if found is None:
            run.emit(SearchFailed(reason=reason))
        else:
            arrived = found.pose
            result.path_to_discovery = found.path_length
            run.emit(
                TargetDetected(
                    instance_id=found.instance_id,
                    position=xyz(found.position),
                    pose=planar(arrived),
                    path_length=round(found.path_length, 4),
                )
            )
            room = self.navmap.room_at(arrived.x, arrived.y)
            goal = self.navmap.nearest_viewpoint(found.position[0], found.position[1], room)
            run.go(goal, result, watch=False, final_yaw=heading(goal, Point(*found.position[:2])))
            run.emit(
                TargetFound(
                    instance_id=found.instance_id,
                    position=xyz(found.position),
                    approach=planar(world.pose()),
                )
            )
            result.success = True
            result.found_instance = found.instance_id
        run.emit(
            TaskEnded(
                target=target, success=result.success, path_length=round(result.path_length, 4)
            )
        )
        return result

    def _pass(
        self,
        run: SearchTask,
        result: SearchResult,
        rooms: Sequence[str],
        room_stops: Mapping[str, Sequence[Stop]],
    ) -> Found | None:
        """One pass of the search over ``room_stops``: the strategy's own (the whole home, or
        room by room in ``rooms``' order), then, with inspection ``cover`` and only when it found
        nothing, the long statics' stretches their N_s may not see, room by room in the same
        order, likeliest stops first."""
        if self.config.method is Method.GLOBAL:
            found = self._search_global(run, result, room_stops)
        else:
            found = self._search_rooms(run, result, rooms, room_stops)
        if found is None and self.config.inspection == "cover":
            for room in rooms:
                for stop in sorted(room_stops[room], key=lambda st: (-st.rel, st.key)):
                    found = run.cover(stop, result)
                    if found:
                        return found
        return found

    def _revisit(
        self,
        run: SearchTask,
        result: SearchResult,
        rooms: Sequence[str],
        room_stops: Mapping[str, Sequence[Stop]],
    ) -> tuple[Found | None, str]:
        """Search the stops again while the mass left at them says the target may still be
        there (a modelled detector misses independently from look to look; a perfect one's
        misses are geometry, which a second look repeats, so it never comes here). Each pass is
        the first's (:meth:`_pass`), over the stops weighted by their value times the chance
        their inspections in this task all missed (:meth:`stop_miss_after`: the target's
        expected size there; one inspection per pass, whatever its views: the target may show
        in only one of them);
        a stop whose weight is below ε / (number of stops) of the total is left out (together
        they hold less than ε). Returns the sighting, or None and why the search stopped."""
        every = [s for stops in room_stops.values() for s in stops]
        total = math.fsum(s.rel for s in every)
        passes = 1
        while True:
            weighted = {
                room: [
                    Stop(s.statics, s.rel * self.stop_miss_after(run.target, s, run.looks_at(s)))
                    for s in stops
                ]
                for room, stops in room_stops.items()
            }
            left = (
                math.fsum(s.rel for stops in weighted.values() for s in stops) / total
                if total > 0
                else 0.0
            )
            if left < REVISIT_EPSILON:
                return None, (
                    f"{run.target} not found: the mass left at the stops is {left:.2%} < "
                    f"ε {REVISIT_EPSILON:.1%} after {passes} pass(es)"
                )
            if passes >= REVISIT_PASSES:
                return None, (
                    f"{run.target} not found: budget of {REVISIT_PASSES} passes spent, "
                    f"{left:.2%} of the mass left at the stops"
                )
            passes += 1
            for sighting, odds in run.undecided():
                found = run.confirm(sighting, result, odds) or run.settle([], result)
                if found is not None:
                    return found, ""
            floor = REVISIT_EPSILON * total / len(every)
            kept = {room: [s for s in stops if s.rel >= floor] for room, stops in weighted.items()}
            found = self._pass(run, result, rooms, kept)
            if found is not None:
                return found, ""

    def _search_rooms(
        self,
        run: SearchTask,
        result: SearchResult,
        rooms: Sequence[str],
        room_stops: Mapping[str, Sequence[Stop]],
    ) -> Found | None:
        """Room by room in ``rooms``' order, each room's stops in planned order."""
        for i, room in enumerate(rooms):
            stops = room_stops[room]
            ordering = self.plan_room(run.world.pose().point, room, rooms[i + 1 :], room_stops)
            ordered = [stops[k] for k in ordering.order]
            run.emit(self._plan(room, rooms[i:], stops, ordering))
            result.plans.append((room, tuple(s.key for s in ordered)))
            for k, stop in enumerate(ordered):
                found = run.go(stop.viewpoint, result) or run.inspect(stop, result)
                if found is None:
                    rest = [*ordered[k + 1 :], *(s for r in rooms[i + 1 :] for s in room_stops[r])]
                    found = self._relook(run, result, stop, rest)
                if found:
                    return found
        return None

    def _search_global(
        self, run: SearchTask, result: SearchResult, room_stops: Mapping[str, Sequence[Stop]]
    ) -> Found | None:
        """The whole-home plan's first room segment, then a new plan from there, until found."""
        remaining = {room: list(stops) for room, stops in room_stops.items()}
        while (plan := self.plan_global(run.world.pose().point, remaining)) is not None:
            stops = remaining[plan.room]
            ordering = Ordering(
                tuple(stops.index(s) for s in plan.order), plan.ordering.terms, plan.ordering.exact
            )
            run.emit(self._plan(plan.room, plan.rooms, stops, ordering))
            result.plans.append((plan.room, tuple(s.key for s in plan.order)))
            for stop in plan.order[: plan.segment]:
                stops.remove(stop)
                found = run.go(stop.viewpoint, result) or run.inspect(stop, result)
                if found is None:
                    rest = [s for left in remaining.values() for s in left]
                    found = self._relook(run, result, stop, rest)
                if found:
                    return found
        return None

    def _relook(
        self, run: SearchTask, result: SearchResult, stop: Stop, rest: Sequence[Stop]
    ) -> Found | None:
        """With relook ``likeliest`` (:data:`~objsearch.agent.detector_model.RELOOKS`), after an
        inspection of ``stop`` that found nothing: inspect it again from where the robot stands
        while its value times the chance its inspections so far in this pass all missed
        (:meth:`stop_miss_after`) is above the value of every stop in ``rest`` (those the
        pass has yet to visit), at most ``REVISIT_PASSES`` inspections in all. A look from where
        the robot stands costs no metres, and the modelled detector's misses are independent
        from look to look, so the likeliest place is looked at again before a farther, less
        likely one (the modelled presets' default since the amendment of 21:12 UTC); with the
        option off (``perfect``, and run specs that name none) it waits for a revisit pass."""
        if self.config.perception.relook != "likeliest" or not rest:
            return None
        best = max(s.rel for s in rest)
        looks = 1
        while (
            looks < REVISIT_PASSES
            and stop.rel * self.stop_miss_after(run.target, stop, looks) > best
        ):
            found = run.go(stop.viewpoint, result) or run.inspect(stop, result)
            if found:
                return found
            looks += 1
        return None

    def _plan(
        self, room: str, room_order: Sequence[str], stops: Sequence[Stop], ordering: Ordering
    ) -> PlanComputed:
        scope = "global-" if self.config.method is Method.GLOBAL else ""
        objective = scope + self.planner.name + ("" if ordering.exact else "-truncated")
        return PlanComputed(
            room=room,
            room_order=tuple(room_order),
            objective=objective,
            alpha=self.planner.alpha,
            candidates=tuple(
                Candidate(
                    static_id=s.key,
                    static_class=s.cls,
                    viewpoint=xy(s.viewpoint),
                    rel=round(s.rel, 12),
                )
                for s in stops
            ),
            order=tuple(stops[k].key for k in ordering.order),
            terms=tuple(round(t, 6) for t in ordering.terms),
            value=round(ordering.value, 6),
        )
