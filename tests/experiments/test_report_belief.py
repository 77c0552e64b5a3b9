"""``bench belief`` from made-up rows: success and SPL beside the oracle ratios, a routine
schedule's evaluation after day 14 and per slot of the day."""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import pytest
from matplotlib.colors import to_hex

from objsearch.agent.errors import ObjsearchError
from objsearch.cli import main
from objsearch.experiments.report_belief import (
    MOVE_SCENE,
    ROUTINE_AFTER,
    curves_figure,
    first_of_scene_lines,
    moved_lines,
    paired_lines,
    ratio_table,
    report,
    run_models,
    select_models,
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


def _twin_rows() -> list[Row]:
    """A stats schedule run with wpl, its no-update twin (bench homes runs both) and the oracle."""
    rows = []
    for scene in range(1, 16):
        rows.append(_row("dist-oracle", "stats-0", scene, 2.0))
        rows.append(_row("wpl", "stats-0", scene, 2.5))
        twin = _row("wpl", "stats-0", scene, 5.0)
        rows.append(replace(twin, update_mode="none", task_id=twin.task_id + "-none"))
    return rows


def test_the_no_update_twin_is_a_row_of_its_own_in_every_table(tmp_path: Path) -> None:
    write_rows(_twin_rows(), tmp_path, "homes_trials")
    text = report([tmp_path])
    table = [line for line in text.splitlines() if line.startswith("| wpl")]
    wpl = next(line for line in table if line.startswith("| wpl |"))
    twin = next(line for line in table if line.startswith("| wpl/none |"))
    # first× all: 2.5 ÷ 2.0 with updates, 5.0 ÷ 2.0 without (merged, both read 1.875).
    assert wpl.split("|")[2].strip() == "1.250" and twin.split("|")[2].strip() == "2.500"
    # Each run's searches counted once per row: 15 days of one target.
    assert wpl.split("|")[6].strip() == "15" and twin.split("|")[6].strip() == "15"


def test_a_table_with_no_row_says_why_instead_of_a_bare_header() -> None:
    # A 3-scene habit run of wpl and global-belief: the ratio table and the paired table were a
    # header with no row and no word of why.
    short = [_row(s, "habit-0", n, 4.0) for s in ("wpl", "global-belief") for n in (1, 2, 3)]
    assert ratio_table(short) == [
        "(no search after scene 10 to tabulate: these runs end at scene 3; "
        "bench homes --scenes-per-schedule sets a run's length)"
    ]
    long = [_row(s, "habit-0", n, 4.0) for s in ("wpl", "global-belief") for n in range(1, 13)]
    assert len(ratio_table(long)) == 4  # header, rule, two rows
    (line,) = paired_lines(long, [("global-belief", "ecost-belief"), ("ecost", "ecost-memory")])
    assert line == (
        "(no pair to compare after day 10: a − b needs both in the same runs, for "
        "global-belief − ecost-belief; these outputs hold global-belief, wpl)"
    )
    both = long + [_row("ecost-belief", "habit-0", n, 3.0) for n in range(1, 13)]
    table = paired_lines(both, [("global-belief", "ecost-belief")])
    assert table[2].startswith("| global-belief − ecost-belief | 1 | 1.00 |")


def _moved_rows(strategies: Sequence[str]) -> list[Row]:
    return [
        _row(s, "moved-0", scene, 2.0 + (scene >= MOVE_SCENE) * (1.0 + i))
        for i, s in enumerate(strategies)
        for scene in range(1, MOVE_SCENE + 5)
    ]


def test_days_worse_than_ecost_say_when_ecost_was_not_run() -> None:
    alone = moved_lines(_moved_rows(["ecost-belief"]))
    assert alone[-1].endswith("| ecost not run |")
    both = moved_lines(_moved_rows(["ecost", "ecost-belief"]))
    rows = {line.split("|")[1].strip(): line.split("|")[-2].strip() for line in both[2:]}
    # ecost-belief is worse than ecost on each of the 5 days from the move; ecost itself: –.
    assert rows == {"ecost": "–", "ecost-belief": "5"}


def _panel_rows() -> list[Row]:
    """Two panels with strategies in other orders, the moved one lacking some (each panel's own
    colour cycle coloured them otherwise than the legend); nine strategies for a wide legend."""
    stats = ["dist-oracle", "dist-oracle-global+cover", "ecost", "ecost-belief", "ecost-memory",
             "ecost-routine-pooled+cover", "global-belief+cover", "wpl", "wpl/none"]  # fmt: skip
    moved = ["global-belief+cover", "wpl", "ecost"]
    rows = [_row(s, "stats-0", n, 2.0 + i / 10) for i, s in enumerate(stats) for n in (1, 2)]
    rows += [_row(s, "moved-0", n, 2.0 + i / 10) for i, s in enumerate(moved) for n in (1, 2)]
    return rows


def test_the_curves_colour_each_strategy_as_the_legend_in_every_panel() -> None:
    fig = curves_figure(_panel_rows())
    (legend,) = fig.legends
    colours = {
        text.get_text(): to_hex(handle.get_color())
        for text, handle in zip(legend.get_texts(), legend.legend_handles, strict=True)
    }
    assert len(colours) == 9 and len(set(colours.values())) == 9
    for ax in fig.axes:
        for line in ax.get_lines():
            if line.get_label() in colours:
                assert to_hex(line.get_color()) == colours[line.get_label()], ax.get_title()


def test_the_curves_legend_fits_the_figure_below_the_panels() -> None:
    fig = curves_figure(_panel_rows())
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    box = fig.legends[0].get_window_extent(renderer)
    assert box.x0 >= 0 and box.y0 >= 0 and box.x1 <= fig.bbox.x1
    labels = min(ax.get_tightbbox(renderer).y0 for ax in fig.axes)
    assert box.y1 <= labels  # under the x axis labels, not over them


def _output(folder: Path, perception: str | None, localisation: str | None = None) -> Path:
    """A bench homes output of made-up rows, run (says its summary.json) with these models."""
    folder.mkdir()
    write_rows(_rows(), folder, "homes_trials")
    summary: dict[str, object] = {}
    if perception is not None:
        summary["perception"] = {"preset": perception}
    if localisation is not None:
        summary["localisation"] = {"preset": localisation}
    (folder / "summary.json").write_text(json.dumps(summary), encoding="utf-8")
    return folder


def test_bench_belief_reports_under_the_detector_its_outputs_were_run_with(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    realistic = _output(tmp_path / "realistic", "realistic", "realistic")
    harsh = _output(tmp_path / "harsh", "harsh")
    old = _output(tmp_path / "old", None)  # written before the models were recorded
    assert run_models(old) == ("perfect", "perfect")
    assert select_models([realistic], "realistic", "realistic") == ("realistic", "realistic")
    with pytest.raises(ObjsearchError, match=r"not run with perception realistic"):
        select_models([realistic, harsh], "realistic")
    with pytest.raises(ObjsearchError, match="different detectors"):
        select_models([realistic, harsh])
    out = tmp_path / "report"
    assert main(["bench", "belief", str(harsh), "--perception", "harsh", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith("perception harsh, localisation perfect; ")
    assert "| ecost-routine |" in printed  # the calibration table, under the named detector
    assert main(["bench", "belief", str(harsh), "--perception", "realistic"]) == 2
    assert "objsearch: error: not run with perception realistic" in capsys.readouterr().err
    assert main(["bench", "belief", str(realistic), str(harsh), "--out", str(out)]) == 2
