"""The new-map measure (experiments/report_newmap.py) on rows whose answer is known: the first
search of the new map's day per run, paired with ecost's on the same run, a run one of them lacks
left out, the ratio of sums per family and pooled, and the verdict; and ``bench belief`` printing
it for an output run with ``--new-map-day``."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import pytest

from objsearch.cli import main
from objsearch.experiments.report_newmap import first_in_new_map, new_map_day, new_map_lines
from objsearch.experiments.runner import Row, write_rows

#: First-search paths on day 11 per home (the same for both schedules).
OURS = {"ithor-01": 4.0, "ithor-03": 6.0, "procthor-01": 10.0, "procthor-02": 12.0}
ECOST = {"ithor-01": 5.0, "ithor-03": 5.0, "procthor-01": 8.0, "procthor-02": 14.0}
#: The run ecost has no search of (so global-belief's is left out too).
LONE = ("procthor-02", "habit-1")


def _row(strategy: str, home: str, seed: int, scene: int, target: str, path: float) -> Row:
    # Task ids order the searches of a run: Apple first, then Cup.
    order = ("Apple", "Cup").index(target)
    return Row(
        "homes", home, f"habit-{seed}", strategy, "all", seed, scene, target, "s", True, path, 1.0,
        f"task-{scene:03d}{order}",
    )  # fmt: skip


def _rows(strategy: str, paths: dict[str, float]) -> list[Row]:
    rows = []
    for home, path in paths.items():
        for seed in (0, 1):
            if strategy.startswith("ecost") and (home, f"habit-{seed}") == LONE:
                continue
            # Listed before the first search: the lowest task id, not the row order, decides.
            rows.append(_row(strategy, home, seed, 11, "Cup", 100.0))
            rows.append(_row(strategy, home, seed, 11, "Apple", path))
            rows.append(_row(strategy, home, seed, 10, "Apple", 1000.0))  # before the new map
    return rows


def _all() -> list[Row]:
    return [
        *_rows("global-belief+cover", OURS),
        *_rows("ecost+cover", ECOST),
        *_rows("dist-oracle-global+cover", dict.fromkeys(OURS, 1.0)),
    ]


def test_the_first_search_of_the_day_is_the_lowest_task_id_of_each_run() -> None:
    firsts = first_in_new_map(_all(), 11)
    assert firsts["global-belief+cover"][("ithor-03", "habit-1")].path_length == 6.0
    assert len(firsts["global-belief+cover"]) == 8
    assert len(firsts["ecost+cover"]) == 7


def test_the_ratio_pairs_runs_and_leaves_out_a_run_one_strategy_lacks() -> None:
    text = "\n".join(new_map_lines(_all(), 11))
    # Paired runs: 7 (procthor-02 habit-1 has no ecost search). Sums: ours 2·4 + 2·6 + 2·10 + 12
    # = 52, ecost 2·5 + 2·5 + 2·8 + 14 = 50: 1.04; iTHOR 20 / 20; ProcTHOR 32 / 30. Runs no
    # longer than ecost's: ithor-01 twice and procthor-02 habit-0.
    assert "| global-belief+cover | iTHOR | 2 | 4 | 5.00 | 5.00 | 1.000 [" in text
    assert "| global-belief+cover | ProcTHOR | 2 | 3 | 10.67 | 10.00 | 1.067 [" in text
    pooled = next(line for line in text.splitlines() if "| pooled |" in line)
    assert pooled.startswith("| global-belief+cover | pooled | 4 | 7 | 7.43 | 7.14 | 1.040 [")
    assert pooled.endswith("(**not shown**) | 3 of 7 |")
    low, high = (float(x) for x in pooled.split("[")[1].split("]")[0].split(", "))
    assert low < 1.04 < high
    assert "global-belief+cover ÷ ecost+cover: procthor-02 habit-1" in text
    # The references and ecost itself are not compared.
    assert "| ecost+cover |" not in text and "| dist-oracle-global+cover |" not in text


def test_a_ci_wholly_at_or_below_one_is_met() -> None:
    rows = [
        *_rows("global-belief+cover", {h: p / 2 for h, p in ECOST.items()}),
        *_rows("ecost+cover", ECOST),
    ]
    text = "\n".join(new_map_lines(rows, 11))
    assert (
        "| global-belief+cover | pooled | 4 | 7 | 3.57 | 7.14 | 0.500 [0.500, 0.500] (met) |"
        in text
    )
    assert "shown when the pooled CI's upper end is ≤ 1 (met), else not shown" in text


def test_without_ecost_or_the_days_searches_it_says_so() -> None:
    assert new_map_lines(_rows("global-belief+cover", OURS), 11)[-1] == (
        "No strategy to compare: ecost not run beside another."
    )
    assert new_map_lines(_all(), 12)[-1] == "No search on day 12 in these runs."


def _output(folder: Path, rows: Sequence[Row], day: int | None) -> Path:
    folder.mkdir()
    write_rows(rows, folder, "homes_trials")
    summary = {"perception": {"preset": "realistic"}, "camera": "occluding", "new_map_day": day}
    (folder / "summary.json").write_text(json.dumps(summary), encoding="utf-8")
    return folder


def test_new_map_day_is_read_from_the_summary(tmp_path: Path) -> None:
    assert new_map_day(_output(tmp_path / "a", _all(), 11)) == 11
    assert new_map_day(_output(tmp_path / "b", _all(), None)) is None
    assert new_map_day(tmp_path) is None  # no summary.json


def test_bench_belief_prints_the_measure_for_runs_in_a_new_map(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "report"
    moved = _output(tmp_path / "moved", _all(), 11)
    argv = ["bench", "belief", "--out", str(out), "--no-progress"]
    assert main([*argv, str(moved)]) == 0
    printed = capsys.readouterr().out
    assert "### First search after a new map (day 11)" in printed
    assert "| global-belief+cover | pooled | 4 | 7 | 7.43 | 7.14 | 1.040 [" in printed
    assert "### First search after a new map" in (out / "belief.md").read_text(encoding="utf-8")
    # A run without a new map: no such block.
    assert main([*argv, str(_output(tmp_path / "same", _all(), None))]) == 0
    assert "new map" not in capsys.readouterr().out
