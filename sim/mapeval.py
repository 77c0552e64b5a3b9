"""How good is a semantic map built from RGB-D? Compared with the home's ground truth, and by what
it costs the search (the same searches run with the ground-truth map and with the built one)."""

from __future__ import annotations

import math
import statistics
import tempfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from objsearch.agent.geometry import Point, Pose, distance, heading, wrap_angle
from objsearch.agent.navmap import NavigationMap
from objsearch.agent.policy import SearchConfig
from objsearch.agent.scene_graph import UpdateMode
from objsearch.agent.semmap import MappedStatic, SemanticMap
from objsearch.agent.session import HomeContext, Session
from objsearch.agent.strategies import RunSpec
from objsearch.agent.world import Detection, DetectionHandler, Navigation
from objsearch.sim.placements import Placement
from objsearch.sim.world import REACH_M, SimClock, SimWorld, with_camera

MATCH_RADIUS_M = 0.5


@dataclass(frozen=True, slots=True)
class InstanceMatch:
    static_id: str  # ground truth
    cls: str
    built_id: str | None  # None: missed
    error_m: float | None  # |loc_s built − loc_s true| on the floor
    same_viewpoint: bool  # the built N_s is the true N_s
    yaw_error: float | None  # |θ_s built − θ_s true|, radians


@dataclass(frozen=True)
class MapAccuracy:
    matches: tuple[InstanceMatch, ...]
    built: int
    spurious: tuple[str, ...]  # built instances that match no true object of their class

    @property
    def found(self) -> int:
        return sum(m.built_id is not None for m in self.matches)

    @property
    def missed(self) -> tuple[str, ...]:
        return tuple(m.static_id for m in self.matches if m.built_id is None)

    @property
    def merged(self) -> int:
        """Built instances that stand for more than one true object (stacked shelves, burners)."""
        ids = [m.built_id for m in self.matches if m.built_id is not None]
        return sum(ids.count(b) > 1 for b in set(ids))

    def summary(self) -> dict[str, Any]:
        errs = sorted(m.error_m for m in self.matches if m.error_m is not None)
        found = [m for m in self.matches if m.built_id is not None]
        return {
            "true_instances": len(self.matches),
            "built_instances": self.built,
            "found": self.found,
            "missed": len(self.missed),
            "spurious": len(self.spurious),
            "merged": self.merged,
            "median_error_m": round(statistics.median(errs), 3) if errs else None,
            "max_error_m": round(errs[-1], 3) if errs else None,
            "same_viewpoint": round(sum(m.same_viewpoint for m in found) / len(found), 3)
            if found
            else None,
            "missed_ids": list(self.missed),
            "spurious_ids": list(self.spurious),
        }


def compare(
    truth: SemanticMap, built: SemanticMap, *, radius: float = MATCH_RADIUS_M
) -> MapAccuracy:
    """Each true static is found by the nearest built instance of its class and room whose box
    contains its centre on the floor, or whose loc_s lies within ``radius`` of it."""

    def near(s: MappedStatic, b: MappedStatic) -> float | None:
        if b.cls != s.cls:
            return None
        d = distance(s.loc, b.loc)
        return d if d <= radius or b.box.contains_xy(s.loc) else None

    matches = []
    for s in truth.statics:
        best: tuple[float, str, MappedStatic] | None = None
        for b in built.in_room(s.room):
            d = near(s, b)
            if d is not None and (best is None or (d, b.id) < best[:2]):
                best = (d, b.id, b)
        if best is None:
            matches.append(InstanceMatch(s.id, s.cls, None, None, False, None))
            continue
        d, _, b = best
        yaw_error = abs(wrap_angle(b.view_yaw - s.view_yaw))
        matches.append(InstanceMatch(s.id, s.cls, b.id, d, b.viewpoint == s.viewpoint, yaw_error))
    spurious = tuple(
        b.id
        for b in built.statics
        if not any(near(s, b) is not None for s in truth.in_room(b.room))
    )
    return MapAccuracy(tuple(matches), len(built.statics), spurious)


class BuiltMapWorld:
    """A :class:`SimWorld` for an agent whose map names static objects its own way.

    ``open(id)`` takes the id of the agent's map: the simulator opens the true container of that
    class nearest the mapped position if the robot can reach it; otherwise the robot only looks
    at the spot (a spurious container in the map has no door)."""

    def __init__(self, world: SimWorld, semmap: SemanticMap) -> None:
        self.world = world
        self._mapped = {s.id: s for s in semmap.statics}

    def pose(self) -> Pose:
        return self.world.pose()

    def now_ns(self) -> int:
        return self.world.now_ns()

    def navigate(
        self,
        goal: Point,
        *,
        on_detection: DetectionHandler | None = None,
        final_yaw: float | None = None,
    ) -> Navigation:
        return self.world.navigate(goal, on_detection=on_detection, final_yaw=final_yaw)

    def look(self, yaw: float, pitch: float = 0.0) -> tuple[Detection, ...]:
        return self.world.look(yaw, pitch)

    def open(self, static_id: str, pitch: float = 0.0) -> tuple[Detection, ...]:
        mapped = self._mapped[static_id]
        here = self.world.pose()
        candidates = [
            s
            for s in self.world.home.room(mapped.room).statics
            if s.container and s.cls == mapped.cls
        ]
        best = min(
            candidates,
            key=lambda s: (
                math.hypot(s.box.center[0] - mapped.loc.x, s.box.center[1] - mapped.loc.y),
                s.id,
            ),
            default=None,
        )
        if best is not None:
            reach = distance(here, Point(best.box.center[0], best.box.center[1]))
            if reach - max(best.box.size[:2]) / 2 <= REACH_M:
                return self.world.open(best.id, pitch)
        return self.world.look(heading(here, mapped.loc), pitch)


@dataclass(frozen=True, slots=True)
class SearchCost:
    target: str
    start: str
    truth_length: float
    built_length: float
    truth_success: bool
    built_success: bool


def search_cost(
    ctx: HomeContext,
    built: SemanticMap,
    placements: Mapping[str, Placement],
    targets: Sequence[str],
    *,
    config: SearchConfig | None = None,
    on_pair: Callable[[SearchCost], None] | None = None,
) -> list[SearchCost]:
    """Every target from every start, once with the true map and once with ``built``; no scene
    graph updates (each search plans with the Visual Genome prior)."""
    config = config or SearchConfig()
    navmap: NavigationMap = ctx.navmap
    built_ctx = replace(ctx, semmap=built)
    out = []
    with tempfile.TemporaryDirectory(prefix="objsearch-mapcost-") as tmp:
        spec = RunSpec.of(
            ctx.home.name,
            ctx.home.digest,
            config.method.value,
            seed=config.seed,
            alpha=config.alpha,
            update_mode=UpdateMode.NONE,
        )
        spec, camera = with_camera(spec)
        sessions = {
            name: Session.start(c, Path(tmp) / name, spec)
            for name, c in (("truth", ctx), ("built", built_ctx))
        }
        # One clock per log, carried from search to search: a new world's clock at 0 would step
        # each log's time back (a warning per search).
        clocks = {name: SimClock(session.resume_time_ns) for name, session in sessions.items()}
        try:
            for target in targets:
                for start, pose in ctx.home.starts.items():
                    w_truth = SimWorld(
                        ctx.home, navmap, placements, pose, camera=camera, clock=clocks["truth"]
                    )
                    r_truth = sessions["truth"].search(w_truth, target, start)
                    w_built = BuiltMapWorld(
                        SimWorld(
                            ctx.home, navmap, placements, pose, camera=camera, clock=clocks["built"]
                        ),
                        built,
                    )
                    r_built = sessions["built"].search(w_built, target, start)
                    pair = SearchCost(
                        target,
                        start,
                        r_truth.path_length,
                        r_built.path_length,
                        r_truth.success,
                        r_built.success,
                    )
                    out.append(pair)
                    if on_pair:
                        on_pair(pair)
        finally:
            for session in sessions.values():
                session.close()
    return out


def cost_summary(pairs: Sequence[SearchCost]) -> dict[str, Any]:
    both = [p for p in pairs if p.truth_success and p.built_success]
    truth = math.fsum(p.truth_length for p in both)
    built = math.fsum(p.built_length for p in both)
    return {
        "searches": len(pairs),
        "success_truth": sum(p.truth_success for p in pairs),
        "success_built": sum(p.built_success for p in pairs),
        "mean_path_truth_m": round(truth / len(both), 3) if both else None,
        "mean_path_built_m": round(built / len(both), 3) if both else None,
        "path_ratio_built_over_truth": round(built / truth, 4) if truth else None,
        "longer": sum(p.built_length > p.truth_length + 1e-9 for p in both),
        "shorter": sum(p.built_length < p.truth_length - 1e-9 for p in both),
    }
