"""A lake made of real simulated logs: the committed v1 log (update mode all) and a fresh run in
update mode targets, so the closed form is checked in both modes and across runs."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE, DayClock
from objsearch.agent.scene_graph import UpdateMode
from objsearch.agent.session import Session, load_context
from objsearch.agent.strategies import RunSpec
from objsearch.events.lake import TableLake, add_log
from objsearch.sim.placements import Schedule
from objsearch.sim.world import SimClock, SimWorld

V1_LOG = Path(__file__).resolve().parents[1] / "events" / "fixtures" / "v1-log"


def write_targets_run(log_dir: Path) -> None:
    ctx = load_context("paper")
    schedule = Schedule.load(ctx.home, "table2")
    starts = list(ctx.home.starts.items())
    spec = RunSpec.for_home(ctx.home, "rvp", seed=3, update_mode=UpdateMode.TARGETS)
    session = Session.start(
        ctx, log_dir, spec, stream="targets", wall_clock=lambda: 1_700_000_000_000_000_000
    )
    try:
        clock = SimClock(session.resume_time_ns)
        for scene in (3, 4):
            for target in ("Phone", "Cup", "Vase"):
                for start_name, pose in starts[1::5]:
                    clock.advance(60.0)
                    world = SimWorld(
                        ctx.home, ctx.navmap, schedule.scenes[scene], pose, clock=clock
                    )
                    # A time of day per scene: the lake's searches carry it (the v1 log has none).
                    at = DayClock(weekday=scene, minute=8 * 60 + 15 * scene)
                    session.search(world, target, start_name, scene=scene, clock=at)
    finally:
        session.close()


@pytest.fixture(scope="session")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    targets = tmp_path_factory.mktemp("logs") / "targets"
    write_targets_run(targets)
    return {"robot": V1_LOG, "targets": targets}


@pytest.fixture(scope="session")
def lake(tmp_path_factory: pytest.TempPathFactory, logs: dict[str, Path]) -> TableLake:
    lake = TableLake(tmp_path_factory.mktemp("lake"), store=STORE)
    for log_dir in logs.values():
        add_log(log_dir, lake, robot="sim")
    return lake
