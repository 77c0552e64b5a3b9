"""The one long-term loop: searching each target from a seeded few of the start points per scene."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.agent.session import load_context
from objsearch.agent.strategies import RunSpec
from objsearch.sim.longterm import day_starts, run_schedule, scenes_of


def test_day_starts_are_a_seeded_draw_per_scene_and_target() -> None:
    starts = load_context("ithor-01").home.starts
    a = day_starts(starts, 2, 0, 1, "Cup")
    assert len(a) == 2 and set(a) <= set(starts)
    assert list(a) == list(day_starts(starts, 2, 0, 1, "Cup"))
    draws = {
        tuple(day_starts(starts, 2, s, scene, t))
        for s in range(3)
        for scene in (1, 2)
        for t in ("Cup", "Apple")
    }
    assert len(draws) > 3  # not the same two points every time
    assert list(day_starts(starts, 99, 0, 1, "Cup")) != []  # all when fewer than asked
    assert len(day_starts(starts, 99, 0, 1, "Cup")) == len(starts)
    with pytest.raises(ValueError, match="at least 1"):
        day_starts(starts, 0, 0, 1, "Cup")


def test_every_strategy_of_a_run_searches_from_the_same_day_starts(tmp_path: Path) -> None:
    ctx = load_context("ithor-01")
    seen = []
    for name in ("wpl", "epl"):
        spec = RunSpec.of("ithor-01", ctx.home.digest, name, seed=3, schedule="habit-3")
        trials = run_schedule(
            tmp_path / name,
            spec,
            targets=("Cup", "Apple"),
            scenes=(1, 2),
            starts_per_search=2,
            skip_absent_targets=True,
        )
        seen.append([(t.scene, t.target, t.start) for t in trials])
        per_day = {(t.scene, t.target) for t in trials}
        assert len(trials) == 2 * len(per_day)
    assert seen[0] == seen[1]


def test_a_seeded_schedule_is_drawn_as_long_as_the_scenes_asked_for(tmp_path: Path) -> None:
    # `bench homes --schedules stats --scenes 15`: scenes 11-15 exist (it was a KeyError)
    from objsearch.experiments.runner import Job, run_job

    job = Job(
        "homes", "ithor-01", "stats-0", "wpl", "all", 0, ("Cup",), (14, 15), starts_per_search=1
    )
    rows = run_job(job)
    assert {r.scene for r in rows} <= {14, 15} and rows
    ten = scenes_of("ithor-01", "stats-0")
    fifteen = scenes_of("ithor-01", "stats-0", upto=15)
    assert sorted(fifteen) == list(range(1, 16)) and sorted(ten) == list(range(1, 11))
