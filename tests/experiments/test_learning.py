"""First search of the day, the excess breakdown and the learning curve of bench rows."""

from __future__ import annotations

import pytest

from objsearch.experiments.learning import curve, excess_breakdown, first_of_day, learning_summary
from objsearch.experiments.runner import Row


def _row(scene: int, target: str, task: int, path: float, oracle: float, wrong: float) -> Row:
    right = path - oracle - wrong - 1.0
    return Row(
        "homes",
        "h",
        "habit-0",
        "wpl",
        "all",
        0,
        scene,
        target,
        f"s{task}",
        True,
        path,
        oracle,
        f"task-{task:05d}",
        (),
        wrong_rooms_m=wrong,
        start_room_m=wrong / 2,
        right_room_m=right,
        approach_m=1.0,
    )


ROWS = [
    _row(1, "Cup", 1, 10.0, 2.0, 5.0),
    _row(1, "Cup", 2, 4.0, 2.0, 0.0),
    _row(2, "Cup", 3, 6.0, 3.0, 1.0),
    _row(2, "Cup", 4, 3.0, 3.0, 0.0),
]


def test_first_of_day_is_the_first_search_per_target_and_scene() -> None:
    assert sorted(r.task_id for r in first_of_day(ROWS)) == ["task-00001", "task-00003"]


def test_parts_sum_to_the_excess() -> None:
    e = excess_breakdown(ROWS)
    assert e["n"] == 4
    assert e["wrong_rooms"] + e["right_room"] + e["approach"] == pytest.approx(e["excess"])


def test_curve_and_summary() -> None:
    c = curve(ROWS)
    assert c["first"] == {1: 5.0, 2: 2.0}
    assert c["all"] == {1: 14.0 / 4.0, 2: 9.0 / 6.0}
    s = learning_summary(ROWS, after=1)["habit"]["wpl"]
    assert s["first_ratio_after"] == 2.0


def test_paired_bootstrap_against_wpl() -> None:
    other = [
        Row(
            r.experiment,
            r.home,
            r.placements,
            "ecost",
            "all",
            r.seed,
            r.scene,
            r.target,
            r.start,
            True,
            r.path_length - 1.0,
            r.oracle_length,
            r.task_id,
        )
        for r in ROWS
    ]
    from objsearch.experiments.learning import paired_bootstrap

    got = paired_bootstrap([*ROWS, *other], resamples=200)
    assert got["ecost"]["mean_diff_m"] == pytest.approx(-1.0)
    assert got["ecost"]["ci_low"] == pytest.approx(-1.0) == got["ecost"]["ci_high"]
