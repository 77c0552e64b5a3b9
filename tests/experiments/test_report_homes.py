"""The held-out homes sections (experiments/report_homes.py) from made-up rows: the paired table
after ``bench homes --inspection cover`` renamed every strategy ``NAME+cover`` (issue 47)."""

from __future__ import annotations

import dataclasses

from objsearch.experiments.report_homes import paired_table
from objsearch.experiments.runner import Row


def _row(strategy: str, home: str, path: float, *, update_mode: str = "all") -> Row:
    return Row(
        "homes", home, "stats-0", strategy, update_mode, 0, 1, "Cup", "kitchen-1", True, path,
        2.0, f"{strategy}-{home}-{update_mode}", (),
    )  # fmt: skip


def _cover_run() -> list[Row]:
    rows = []
    for home in ("ithor-01", "ithor-02"):
        rows += [
            _row("wpl+cover", home, 5.0),
            _row("wpl+cover", home, 7.0, update_mode="none"),
            _row("global-belief+cover", home, 4.0),
        ]
    return rows


def test_a_cover_run_is_paired_with_wpl_cover() -> None:
    lines = paired_table(_cover_run())
    assert "vs wpl (wpl+cover for a cover run)" in lines[0]
    cells = {line.split("|")[1].strip(): line.split("|")[2].strip() for line in lines[2:]}
    # Path to discovery of a found search is its path: 4 − 5 and 7 − 5 m on both runs.
    assert cells == {"global-belief+cover": "-1.00", "wpl+cover/none": "+2.00"}


def test_without_a_wpl_to_pair_with_it_names_what_was_run() -> None:
    rows = [r for r in _cover_run() if r.strategy == "global-belief+cover"]
    rows += [dataclasses.replace(rows[0], strategy="wpl")]  # another inspection: no pair
    (line,) = paired_table(rows)
    assert "these outputs hold global-belief+cover, wpl" in line
    assert "wpl among --strategies" not in line
