"""The paper's long-term experiment (§6.1.2): every scene of a schedule, every target, every start."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from objsearch.agent.errors import DataFileError
from objsearch.agent.planner import StopPlanner
from objsearch.agent.policy import SearchConfig
from objsearch.agent.relations import RelationModel
from objsearch.agent.scene_graph import UpdateMode
from objsearch.agent.session import Session, load_context
from objsearch.sim.schedules import load_schedule
from objsearch.sim.world import SimClock, SimWorld, WorldObserver

TARGET_ORDER = ("Apple", "Cup", "Bowl", "Phone", "Laptop", "Pillow", "Vase", "ToiletPaper")
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


def run_schedule(
    home_name: str,
    log_dir: Path,
    config: SearchConfig,
    update_mode: UpdateMode,
    *,
    schedule_name: str = "table2",
    targets: Sequence[str] = TARGET_ORDER,
    scenes: Sequence[int] | None = None,
    starts: Sequence[str] | None = None,
    on_trial: Callable[[Trial], None] | None = None,
    observer: WorldObserver | None = None,
    params: Mapping[str, object] | None = None,
    graph: RelationModel | None = None,
    planner: StopPlanner | None = None,
) -> list[Trial]:
    """Search every target from every start in every scene, in that order, on one log.

    ``schedule_name`` is any schedule ``sim/schedules.py`` knows: ``table2``, ``stats-<seed>`` or
    ``rearr-<seed>``. Each search is one task: the scene graph is updated (per ``update_mode``) when it ends, so the
    next search, whatever its start, plans with what the previous ones saw. ``starts`` picks
    start points by name (default: all of the home's); ``observer`` sees every pose and camera
    frame (what ``objsearch record`` writes to a bag). ``params`` go into ``run_started`` beside
    the schedule's name; ``graph`` and ``planner`` pick another strategy than the paper's
    (``Session``'s defaults).
    """
    ctx = load_context(home_name)
    schedule = load_schedule(ctx.home, schedule_name)
    all_starts = ctx.home.starts
    for name in starts or ():
        ctx.home.start(name)  # an unknown start fails before anything is written
    chosen = {name: all_starts[name] for name in starts} if starts else all_starts
    unknown_scenes = sorted(set(scenes or ()) - set(schedule.scenes))
    if unknown_scenes:
        raise DataFileError(
            f"schedule {schedule_name!r} has scenes {sorted(schedule.scenes)}, not {unknown_scenes}"
        )
    trials: list[Trial] = []
    session = Session(
        ctx,
        log_dir,
        config,
        update_mode,
        params={"schedule": schedule_name, **(params or {})},
        graph=graph,
        planner=planner,
    )
    try:
        clock = SimClock(session.resume_time_ns)
        for scene in scenes or sorted(schedule.scenes):
            placements = schedule.scenes[scene]
            for target in targets:
                for start_name, pose in chosen.items():
                    clock.advance(PAUSE_BETWEEN_TASKS_S)
                    world = SimWorld(
                        ctx.home, ctx.navmap, placements, pose, clock=clock, observer=observer
                    )
                    oracle = world.oracle_length(target)
                    result = session.search(world, target, start_name, scene=scene)
                    trial = Trial(
                        scene,
                        target,
                        start_name,
                        result.success,
                        result.path_length,
                        oracle,
                        result.task_id,
                    )
                    trials.append(trial)
                    if on_trial:
                        on_trial(trial)
    finally:
        session.close()
    return trials
