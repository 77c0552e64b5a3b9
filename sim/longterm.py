"""The paper's long-term experiment (§6.1.2), and the one loop every long-term run goes through:
every scene of a placement source, every target, every start, on one log.

``objsearch demo``, ``objsearch record``, ``objsearch bench`` (experiments/runner.py) and the golden
logs (experiments/golden.py) all call :func:`run_schedule`; nothing else walks scenes × targets × starts.
"""

from __future__ import annotations

import random
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from objsearch.agent.categories import Category
from objsearch.agent.errors import DataFileError
from objsearch.agent.geometry import Point, Pose
from objsearch.agent.map_frames import Rigid2D
from objsearch.agent.maps import DEFAULT_MAP, next_map
from objsearch.agent.results import SearchResult
from objsearch.agent.session import HomeContext, Session, load_context
from objsearch.agent.strategies import RunSpec
from objsearch.sim.detector_model import with_perception
from objsearch.sim.localisation import with_localisation
from objsearch.sim.map_frame import MovedMapWorld, draw_frame, frame_mode, recorded_frame
from objsearch.sim.models import SIM_MODELS
from objsearch.sim.placements import Placements, base_placements, table1_removals
from objsearch.sim.schedule_names import load_schedule, schedule_clock
from objsearch.sim.seeable import seeable_scenes
from objsearch.sim.world import (
    SimClock,
    SimWorld,
    WorldObserver,
    with_camera,
)

TARGET_ORDER = ("Apple", "Cup", "Bowl", "Phone", "Laptop", "Pillow", "Vase", "ToiletPaper")
#: Simulated time between two searches (s): the robot's clock moves on between tasks.
PAUSE_BETWEEN_TASKS_S = 60.0


@dataclass(frozen=True, slots=True)
class Trial:
    scene: int
    target: str
    start: str
    success: bool
    path_length: float
    oracle_length: float
    task_id: str
    route: tuple[Point, ...] = ()
    #: Metres from the start to the detection of the target (the paper's path length); the
    #: whole path when the target was never found.
    path_to_discovery: float | None = None
    #: The agent said found, but the instance it found is no placed target (a modelled
    #: detector's false positive or confusion): counted as a failure (``success`` is False).
    false_found: bool = False


def scenes_of(
    home_name: str, source: str, *, upto: int | None = None, data: Path | None = None
) -> dict[int, Placements]:
    """Scene number → placements for a placement source: ``table1`` (the paper's Table I scene,
    as scene 0), or any schedule ``sim/schedule_names.py`` knows (``table2``, ``stats-<seed>``,
    ``rearr-<seed>``, ``habit-<seed>``). A seeded schedule is drawn with ``upto`` scenes (default:
    its kind's own length); the draw is sequential, so its first scenes are the same whatever
    the length. The home and the schedule's data are those of the data folder ``data`` (None:
    ``datapaths.data_dir()``)."""
    ctx = load_context(home_name, data)
    if source == "table1":
        return {0: base_placements(ctx.home, table1_removals(ctx.home, data=data))}
    return dict(load_schedule(ctx.home, source, scenes=upto, data=data).scenes)


def run_schedule(
    log_dir: Path,
    spec: RunSpec,
    *,
    targets: Sequence[str] = TARGET_ORDER,
    scenes: Sequence[int] | None = None,
    starts: Sequence[str] | None = None,
    starts_per_search: int | None = None,
    placements: Mapping[int, Placements] | None = None,
    skip_absent_targets: bool = False,
    on_trial: Callable[[Trial], None] | None = None,
    observer: WorldObserver | None = None,
    keep_routes: bool = False,
    data: Path | None = None,
    **session_options: Any,
) -> list[Trial]:
    """Search every target from every start in every scene, in that order, on one log.

    The placements come from ``placements`` (scene → placements) or else from the spec's
    ``schedule`` (see :func:`scenes_of`), without those no viewpoint can see
    (``sim/seeable.py``): a target left with no seeable instance in a scene is not searched for
    there (``objsearch bench`` reports them). Each search is one task: the scene graph is updated
    (per the spec's update mode) when it ends, so the next search, whatever its start, plans with
    what the previous ones saw. ``starts`` picks start points by name (default: all of the
    home's); ``starts_per_search`` instead searches each target from that many of them per scene,
    drawn anew for each (scene, target) from the spec's seed (:func:`day_starts`); with
    ``skip_absent_targets`` a target the scene does not hold is not searched for;
    ``observer`` sees every pose and camera frame (what ``objsearch record`` writes to a bag).
    ``session_options`` go to :meth:`Session.start` (``wall_clock``, ``stream``, ...). All that
    the run reads is of the data folder ``data`` (None: ``datapaths.data_dir()``).
    """
    ctx = load_context(spec.home, data)
    spec, camera = with_camera(spec)
    spec, detector = with_perception(spec, movable=ctx.vocabulary.names(Category.SEMI_DYNAMIC))
    spec, localiser = with_localisation(spec)
    # From this scene on the robot runs in a new map (a new session: run_started with its id),
    # in the old map's frame or one of its own (an unknown mode fails before anything is written).
    new_map_day, frame = spec.params.get("new_map_day"), _no_frame(spec.params)
    placements, unseeable = _seeable_placements(ctx, spec, placements, scenes)
    chosen = _chosen_starts(ctx, starts)
    trials: list[Trial] = []
    inputs = {
        "targets": list(targets),
        "scenes": None if scenes is None else list(scenes),
        "starts": None if starts is None else list(starts),
        **({"starts_per_search": starts_per_search} if starts_per_search else {}),
        "skip_absent_targets": skip_absent_targets,
    }
    session_options.setdefault("inputs", inputs)
    session_options.setdefault("models", SIM_MODELS)
    session = Session.start(ctx, log_dir, spec, **session_options)
    try:
        clock = SimClock(session.resume_time_ns)
        for scene in scenes or sorted(placements):
            if new_map_day is not None and scene >= int(new_map_day):
                frame, new_map_day = _start_new_map(session, spec), None
            scene_placements = placements[scene]
            present = {p.cls for p in scene_placements.values()}
            for target in targets:
                if target not in present and (skip_absent_targets or target in unseeable[scene]):
                    continue
                todays = (
                    day_starts(chosen, starts_per_search, spec.seed, scene, target)
                    if starts_per_search
                    else chosen
                )
                for start_name, pose in todays.items():
                    clock.advance(PAUSE_BETWEEN_TASKS_S)
                    if detector is not None:
                        detector.begin(scene, target, start_name)
                    world = SimWorld(
                        ctx.home,
                        ctx.navmap,
                        scene_placements,
                        pose,
                        clock=clock,
                        camera=camera,
                        observer=observer,
                        detector=detector,
                        localiser=localiser,
                    )
                    oracle = world.oracle_length(
                        target, min_mask_px=ctx.vocabulary.classes[target].min_mask_area_px
                    )
                    result = session.search(
                        world if frame is None else MovedMapWorld(world, frame),
                        target,
                        start_name,
                        scene=scene,
                        clock=schedule_clock(spec.schedule, scene),
                    )
                    real = world.is_instance_of(result.found_instance, target)
                    trial = _trial(scene, target, start_name, result, real, oracle, keep_routes)
                    trials.append(trial)
                    if on_trial:
                        on_trial(trial)
    finally:
        session.close()
    return trials


def _chosen_starts(ctx: HomeContext, starts: Sequence[str] | None) -> Mapping[str, Pose]:
    """The named starts of the home (default: all); an unknown one fails before anything is
    written."""
    every = ctx.home.starts
    for name in starts or ():
        ctx.home.start(name)
    return {name: every[name] for name in starts} if starts else every


def _no_frame(params: Mapping[str, Any]) -> Rigid2D | None:
    """No frame yet: the robot starts in its first map (``new_map_frame`` validated now)."""
    frame_mode(params)
    return None


def _start_new_map(session: Session, spec: RunSpec) -> Rigid2D | None:
    """Start the session's next map, in the old map's frame (None) or, with ``new_map_frame``
    ``moved``, in a frame of its own (sim/map_frame.py): drawn from the seed and the map's id
    unless the spec records one, recorded in its ``run_started``, and returned."""
    if frame_mode(spec.params) != "moved":
        session.start_run(spec, new_map=True)
        return None
    new_map = next_map(session.state.maps.current or DEFAULT_MAP)
    frame = recorded_frame(spec.params) or draw_frame(spec.seed, new_map)
    session.start_run(
        spec.with_changes(params={**spec.params, "map_frame": frame.params()}), new_map=True
    )
    return frame


def _trial(
    scene: int,
    target: str,
    start: str,
    result: SearchResult,
    real: bool,
    oracle: float,
    keep_route: bool,
) -> Trial:
    """One search's trial: a "found" on a false sighting (``real`` false) is a failure."""
    return Trial(
        scene,
        target,
        start,
        result.success and real,
        result.path_length,
        oracle,
        result.task_id,
        tuple(result.route) if keep_route else (),
        result.path_length if result.path_to_discovery is None else result.path_to_discovery,
        false_found=result.success and not real,
    )


def _seeable_placements(
    ctx: HomeContext,
    spec: RunSpec,
    placements: Mapping[int, Placements] | None,
    scenes: Sequence[int] | None,
) -> tuple[dict[int, Placements], dict[int, set[str]]]:
    """The run's placements by scene (given, or the spec's schedule's) without those no viewpoint
    can see, and per scene the classes left with no seeable instance; an error if ``scenes``
    names one the schedule does not have."""
    if placements is None:
        if spec.schedule is None:
            raise DataFileError("a long-term run needs placements or a schedule in its spec")
        placements = scenes_of(spec.home, spec.schedule, data=ctx.data)
    seeable, dropped = seeable_scenes(ctx.home, placements, ctx.data)
    unseeable: dict[int, set[str]] = {n: set() for n in seeable}
    for u in dropped:
        unseeable[u.scene].add(u.cls)
    unknown_scenes = sorted(set(scenes or ()) - set(seeable))
    if unknown_scenes:
        raise DataFileError(
            f"schedule {spec.schedule!r} has scenes {sorted(seeable)}, not {unknown_scenes}"
        )
    return seeable, unseeable


def day_starts(
    starts: Mapping[str, Pose], count: int, seed: int, scene: int, target: str
) -> dict[str, Pose]:
    """``count`` of ``starts`` (all if fewer), in the order they are searched from: a seeded draw
    per (seed, scene, target), so every strategy of a run searches from the same points and the
    first of them is the first search of the day."""
    if count < 1:
        raise ValueError(f"starts per search must be at least 1, not {count}")
    rng = random.Random(f"day-starts/{seed}/{scene}/{target}")
    picked = rng.sample(sorted(starts), min(count, len(starts)))
    return {name: starts[name] for name in picked}
