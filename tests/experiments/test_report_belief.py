"""``bench belief`` from made-up rows: success and SPL beside the oracle ratios, a routine
schedule's evaluation after day 14 and per slot of the day."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.experiments.report_belief import ROUTINE_AFTER, ratio_table, report, slot_lines
from objsearch.experiments.runner import Row, write_rows


def _row(strategy: str, schedule: str, scene: int, path: float, *, success: bool = True) -> Row:
    return Row(
        "homes",
        "ithor-01",
        schedule,
        strategy,
        "all",
        0,
        scene,
        "Cup",
        "kitchen",
        success,
        path,
        2.0,
        f"{strategy}-{schedule}-{scene}",
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
