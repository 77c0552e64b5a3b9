"""First search of the day, the excess breakdown and the learning curve of bench rows."""

from __future__ import annotations

import dataclasses
import json

import pytest

from objsearch.experiments.learning import (
    curve,
    excess_breakdown,
    first_of_day,
    learning_summary,
    paired_differences,
    paired_json,
    render_learning,
    run_curves,
)
from objsearch.experiments.runner import Row
from objsearch.experiments.stats import CI, MIN_RUNS, RANGE


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


def test_parts_sum_to_the_path_and_none_is_negative() -> None:
    e = excess_breakdown(ROWS)
    assert e["n"] == 4
    assert e["wrong_rooms"] + e["right_room"] + e["approach"] == pytest.approx(e["path"])
    assert e["path"] - e["oracle"] == pytest.approx(e["excess"])
    # Row 4 walked less in the right room than the oracle's whole walk (its right room net of
    # the oracle is -1 m): as a part of the path it is +2 m, never negative.
    assert ROWS[3].right_room_m == -1.0
    assert min(e[p] for p in ("wrong_rooms", "start_room", "right_room", "approach")) >= 0
    assert excess_breakdown([ROWS[3]])["right_room"] == pytest.approx(2.0)


def test_curve_and_summary() -> None:
    c = curve(ROWS)
    assert c["first"] == {1: 5.0, 2: 2.0}
    assert c["all"] == {1: 14.0 / 4.0, 2: 9.0 / 6.0}
    s = learning_summary(ROWS, after=1)["habit"]["wpl"]
    assert s["first_ratio_after"] == 2.0
    # One run: each scene's per-run value is the run's own ratio.
    assert run_curves(ROWS) == {"all": {1: [3.5], 2: [1.5]}, "first": {1: [5.0], 2: [2.0]}}


def test_a_run_of_no_scene_after_the_cut_prints_a_dash_not_nan() -> None:
    # A short run (3 scenes) has no ratio after scene 10: the table printed "nan", summary.json
    # NaN (no JSON at all).
    summary = learning_summary(ROWS)
    s = summary["habit"]["wpl"]
    assert s["all_ratio_after"] is None and s["first_ratio_after"] is None
    json.dumps(summary, allow_nan=False)
    (line,) = (x for x in render_learning(summary).splitlines() if x.startswith("  wpl "))
    assert "nan" not in line and line.split()[-2:] == ["–", "–"]
    line = render_learning(learning_summary(ROWS, after=1)).splitlines()[-1]
    assert line.split()[-1] == "2.00"


def _shifted(rows: list[Row], strategy: str, by: float) -> list[Row]:
    return [dataclasses.replace(r, strategy=strategy, path_length=r.path_length + by) for r in rows]


def test_paired_differences_give_the_range_under_min_runs() -> None:
    # One run (home h, habit-0) per strategy: no interval, n and the range instead.
    got = paired_differences([*ROWS, *_shifted(ROWS, "ecost", -1.0)])["ecost"]
    assert (got.n, got.kind) == (1, RANGE)
    assert got.mean == got.low == got.high == pytest.approx(-1.0)
    assert "no CI" in got.text() and "n = 1" in got.text()


def test_paired_differences_give_a_ci_over_enough_runs() -> None:
    # MIN_RUNS runs (one per home) of wpl, and ecost shorter by 1 m + 0.1 m × the run's number.
    rows: list[Row] = []
    for i in range(MIN_RUNS):
        wpl = [dataclasses.replace(r, home=f"h{i}") for r in ROWS]
        rows += [*wpl, *_shifted(wpl, "ecost", -1.0 - 0.1 * i)]
    got = paired_differences(rows)["ecost"]
    assert (got.n, got.kind) == (MIN_RUNS, CI)
    assert got.low < got.mean < got.high
    assert got.low > -1.0 - 0.1 * (MIN_RUNS - 1) and got.high < -1.0
    assert paired_json({"ecost": got})["ecost"]["ci_low"] == got.low


def test_a_cover_run_pairs_with_wpl_of_its_own_inspection() -> None:
    # bench homes --inspection cover names every strategy NAME+cover, wpl too (and its no-update
    # twin wpl+cover/none): each pairs with wpl+cover, a plain run with plain wpl.
    cover = _shifted(ROWS, "wpl+cover", 0.0)
    twin = [dataclasses.replace(r, update_mode="none") for r in _shifted(ROWS, "wpl+cover", 2.0)]
    plain = [*ROWS, *_shifted(ROWS, "ecost", -1.0)]
    got = paired_differences([*cover, *_shifted(ROWS, "ecost+cover", -0.5), *twin, *plain])
    assert set(got) == {"ecost+cover", "wpl+cover/none", "ecost"}
    assert got["ecost+cover"].mean == pytest.approx(-0.5)
    assert got["wpl+cover/none"].mean == pytest.approx(2.0)
    assert got["ecost"].mean == pytest.approx(-1.0)
