"""``bench belief`` from made-up rows: success and SPL beside the oracle ratios, a routine
schedule's evaluation after day 14 and per slot of the day."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.experiments.report_belief import (
    ROUTINE_AFTER,
    first_of_scene_lines,
    ratio_table,
    report,
    slot_lines,
)
from objsearch.experiments.runner import Row, write_rows


def _row(
    strategy: str,
    schedule: str,
    scene: int,
    path: float,
    *,
    success: bool = True,
    target: str = "Cup",
) -> Row:
    return Row(
        "homes",
        "ithor-01",
        schedule,
        strategy,
        "all",
        0,
        scene,
        target,
        "kitchen",
        success,
        path,
        2.0,
        f"{strategy}-{schedule}-{scene}-{target}",
    )


def _rows() -> list[Row]:
    rows = []
    for scene in range(1, ROUTINE_AFTER + 9):  # two days after day 14
        rows.append(_row("dist-oracle", "routine-0", scene, 3.0))
        rows.append(_row("ecost-routine", "routine-0", scene, 2.5, success=scene % 8 != 0))
    return rows


def test_success_and_spl_stand_beside_the_oracle_ratio() -> None:
    lines = ratio_table(_rows(), ROUTINE_AFTER)
    assert "SPL after 56" in lines[0] and "÷ dist-oracle after scene 56" in lines[0]
    routine = next(line for line in lines if line.startswith("| ecost-routine"))
    cells = [c.strip() for c in routine.strip("|").split("|")]
    # After scene 56: 8 searches, one failed (scene 64); SPL = 7/8 × 2.0/2.5.
    assert cells[6] == "87.50%"
    assert float(cells[7]) == pytest.approx(7 / 8 * 2.0 / 2.5, abs=1e-3)
    assert cells[3].startswith("0.833")  # 2.5 / 3.0 against the oracle (n=1: no CI)


def test_routine_slots_and_the_written_report(tmp_path: Path) -> None:
    rows = _rows()
    slots = slot_lines(rows)
    assert slots[0].startswith("| strategy (first× after scene 56) | morning | afternoon")
    assert slots[-1].endswith("| – |")  # days 15 and 16 are a Monday and a Tuesday
    write_rows(rows, tmp_path, "homes_trials")
    text = report([tmp_path])
    assert "### routine schedules" in text and "ecost-routine − dist-oracle" in text


def test_a_routine_home_is_also_read_on_the_first_search_of_each_scene_and_day() -> None:
    rows = []
    for scene in range(ROUTINE_AFTER + 1, ROUTINE_AFTER + 9):  # days 15 and 16, four slots each
        for strategy, first, later, dawn in (
            ("dist-oracle", 4.0, 2.0, 1.0),
            ("ecost-routine", 3.0, 3.0, 0.5),
        ):
            # Apple comes before Cup in the targets' order: the scene's first search.
            rows.append(_row(strategy, "routine-0", scene, later, target="Cup"))
            morning = (scene - 1) % 4 == 0
            rows.append(
                _row(strategy, "routine-0", scene, dawn if morning else first, target="Apple")
            )
    lines = first_of_scene_lines(rows)
    scenes = lines.index("First search of each scene (one a time of day, four a day):")
    days = lines.index("First search of each day (the morning scene's first search):")
    per_scene = next(x for x in lines[scenes:days] if x.startswith("| ecost-routine |"))
    per_day = next(x for x in lines[days:] if x.startswith("| ecost-routine |"))
    # Cup, the scenes' later search, is left out; the mornings alone make the days.
    ratio_scene = (0.5 * 2 + 3.0 * 6) / (1.0 * 2 + 4.0 * 6)
    assert per_scene.split("|")[4].strip().startswith(f"{ratio_scene:.3f}")
    assert per_day.split("|")[4].strip().startswith(f"{0.5 / 1.0:.3f}")
    assert any("ecost-routine − dist-oracle" in x for x in lines[scenes:days])
