"""bench belief's tables on rows whose answer is known: the reference is the oracle that walks
less, and the usual-place table keeps the days the schedule put the target at its usual place."""

from __future__ import annotations

import json
from pathlib import Path

from objsearch.agent.home import load_home
from objsearch.experiments.report_belief import (
    ratio_table,
    read_outputs,
    report,
    trend_lines,
    usual_place_lines,
)
from objsearch.experiments.runner import Row, write_rows
from objsearch.sim.habit_schedule import habit_schedule, habits
from objsearch.sim.longterm import TARGET_ORDER

HOME = "ithor-01"


def _row(
    strategy: str, scene: int, target: str, path: float, oracle: float, home: str = HOME
) -> Row:
    return Row(
        experiment="homes",
        home=home,
        placements="habit-0",
        strategy=strategy,
        update_mode="all",
        seed=0,
        scene=scene,
        target=target,
        start="s",
        success=True,
        path_length=path,
        oracle_length=oracle,
        task_id=f"{home}-{strategy}-{scene:03d}-{target}",
    )


def _rows(strategy: str, factor: float) -> list[Row]:
    return [
        _row(strategy, scene, target, factor * (3.0 + i), 3.0 + i)
        for scene in (11, 12, 13)
        for i, target in enumerate(TARGET_ORDER)
    ]


def test_each_table_reads_against_the_oracle_that_walks_less() -> None:
    rows = (
        _rows("global-belief", 2.0) + _rows("dist-oracle", 1.5) + _rows("dist-oracle-global", 1.0)
    )
    table = "\n".join(ratio_table(rows))
    assert "÷ dist-oracle-global after scene 10" in table
    assert "| global-belief | 2.000 |" in table and "| 2.000 (n=1) |" in table


def test_the_usual_place_table_keeps_the_days_the_target_was_at_its_usual_place() -> None:
    rows = _rows("global-belief", 2.0) + _rows("dist-oracle", 1.0)
    home = load_home(HOME)
    usual = habits(home, 0)
    at_usual = sum(
        p.support == usual[p.cls].usual
        for scene, placed in habit_schedule(home, 0, scenes=13).scenes.items()
        if scene > 10
        for p in placed.values()
        if p.cls in TARGET_ORDER
    )
    assert 0 < at_usual < 3 * len(TARGET_ORDER)
    lines = usual_place_lines(rows)
    assert f"| global-belief | {at_usual} | 2.000 | 2.000 |" in lines
    assert f"| dist-oracle | {at_usual} | 1.000 | – |" in lines


def test_a_cover_run_pairs_with_the_same_strategy_without_it(tmp_path: Path) -> None:
    for name, inspection, factor in (("single", "single", 1.0), ("cover", "cover", 1.5)):
        folder = tmp_path / name
        folder.mkdir()
        write_rows(_rows("global-belief", factor), folder, "homes_trials")
        (folder / "summary.json").write_text(json.dumps({"inspection": inspection}))
    rows = read_outputs([tmp_path / "single", tmp_path / "cover"])
    assert {r.strategy for r in rows} == {"global-belief", "global-belief+cover"}
    text = report([tmp_path / "single", tmp_path / "cover"])
    assert "| global-belief+cover − global-belief | 1 |" in text


def test_a_report_of_cover_runs_alone_reads_them_against_each_other(tmp_path: Path) -> None:
    """Every strategy searched with ``cover``: the reference and the pairs are the cover twins."""
    folder = tmp_path / "cover"
    folder.mkdir()
    rows = [
        *_rows("dist-oracle-global", 1.0),
        *_rows("global-belief", 1.2),
        *_rows("ecost-belief", 1.5),
    ]
    write_rows(rows, folder, "homes_trials")
    (folder / "summary.json").write_text(json.dumps({"inspection": "cover"}))
    text = report([folder])
    assert "÷ dist-oracle-global+cover after scene 10" in text
    assert "| global-belief+cover − ecost-belief+cover | 1 |" in text
    assert "| global-belief+cover − dist-oracle-global+cover | 1 |" in text


def test_the_learning_curve_is_read_against_the_reference_block_by_block() -> None:
    """Days 1-8 in four blocks of two; the belief walks 2.0x the oracle's path on days 1-2, then
    1.5x; the reference's own day-to-day difficulty (x1, then x3) cancels."""
    rows = [
        _row(name, scene, "Cup", factor * 4.0, 4.0, home)
        for home in ("ithor-01", "ithor-02")
        for scene in range(1, 9)
        for name, factor in (
            ("dist-oracle-global", 1.0 if scene <= 4 else 3.0),
            ("global-belief", (1.0 if scene <= 4 else 3.0) * (2.0 if scene <= 2 else 1.5)),
        )
    ]
    lines = trend_lines(rows)
    assert "first search ÷ dist-oracle-global's on the same runs and days" in lines[0]
    assert "| days 1–2 | days 3–4 | days 5–6 | days 7–8 | Δ 1–2 → 3–4 |" in lines[2]
    row = next(line for line in lines if line.startswith("| global-belief |"))
    assert row == (
        "| global-belief | 2.000 | 1.500 | 1.500 | 1.500 | -0.500 (n=2) | +0.000 (n=2) "
        "| +0.000 (n=2) |"
    )
