"""The perception protocol's measures (experiments/report_protocol.py) on rows whose answer is
known: ratios of sums paired over homes, ÷ perfect, every-place ECE, the default-strategy and
threshold rule, and every failure with its cause."""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import pytest

from objsearch.cli import main
from objsearch.experiments.report_protocol import (
    calibration_lines,
    failure_lines,
    family,
    headline_lines,
    paired_ratio,
    protocol_lines,
    rule_lines,
)
from objsearch.experiments.runner import Row, write_rows

HOMES = ("ithor-01", "ithor-03", "procthor-01", "procthor-02")


def _row(strategy: str, home: str, scene: int, target: str, path: float, **kw: object) -> Row:
    row = Row(
        "homes", home, "habit-0", strategy, "all", 0, scene, target, "s", True, path, 1.0,
        f"{home}-{strategy}-{scene:03d}-{target}",
    )  # fmt: skip
    return replace(row, **kw)  # type: ignore[arg-type]


def _run(strategy: str, factor: dict[str, float]) -> list[Row]:
    return [
        _row(strategy, home, scene, target, factor[home] * (2.0 + i))
        for home in HOMES
        for scene in (9, 11, 12)
        for i, target in enumerate(("Apple", "Cup"))
    ]


def test_families_put_held_out_houses_with_procthor() -> None:
    assert [family(h) for h in ("ithor-23", "procthor-07", "klbr-8")] == [
        "iTHOR",
        "ProcTHOR",
        "ProcTHOR",
    ]


def test_the_headline_is_a_ratio_of_sums_after_day_10_with_a_ci_over_homes() -> None:
    ref = _run("dist-oracle-global+cover", dict.fromkeys(HOMES, 1.0))
    # Scene 9 is before the headline's days: doubling it changes nothing.
    ours = [
        replace(r, path_length=r.path_length * (100.0 if r.scene == 9 else 1.0))
        for r in _run("global-belief+cover", {"ithor-01": 1.0, "ithor-03": 1.2, **dict.fromkeys(HOMES[2:], 1.1)})
    ]  # fmt: skip
    value, low, high, homes, n = paired_ratio(
        {(r.home, r.seed, r.scene, r.target, r.start): r for r in ours if r.scene > 10},
        {(r.home, r.seed, r.scene, r.target, r.start): r for r in ref if r.scene > 10},
    )
    assert (homes, n) == (4, 16)
    assert abs(value - 1.1) < 1e-9
    assert 1.0 <= low < value < high <= 1.2
    table = "\n".join(headline_lines(ours + ref, perfect=[replace(r, path_length=r.path_length / 2) for r in ours]))  # fmt: skip
    # iTHOR: (1.0 + 1.2) / 2 = 1.1; ProcTHOR 1.1; ÷ perfect 2.0 everywhere, which misses 1.25.
    assert (
        "| global-belief+cover | iTHOR | 2 | 8 | 1.100 [1.000, 1.200] (met) | 2.000 [2.000, 2.000] (**not met**) |"
        in table
    )
    assert "| global-belief+cover | pooled | 4 | 16 | 1.100 [" in table


def test_ece_over_every_place_bins_each_places_probability() -> None:
    # Each search: the found place at 0.5, two others at 0.25: every place says 0.25 → 0 of 2,
    # 0.5 → 1 of 1: ECE = 2/3 · 0.25 + 1/3 · 0.5 = 1/3; the top place (0.5, hit) 0.5.
    rows = [
        _row("global-belief+cover", h, 11, "Cup", 1.0, belief_top_p=0.5, belief_top_hit=True,
             belief_p_found=0.5, belief_brier=0.375, belief_others="0.25 0.25")
        for h in HOMES
    ]  # fmt: skip
    table = "\n".join(calibration_lines(rows))
    assert "| global-belief+cover | pooled | 4 | 0.3333 | 0.5000 | 0.3750 |" in table
    # A run written before every place was recorded: no every-place ECE of the rest alone.
    rows[0] = replace(rows[0], belief_others=None)
    table = "\n".join(calibration_lines(rows))
    assert "| global-belief+cover | pooled | 4 | – (not recorded for 1 of 4) | 0.5000 |" in table


def test_the_default_changes_only_for_a_strategy_lower_with_a_ci_excluding_one() -> None:
    ref = _run("dist-oracle-global+cover", dict.fromkeys(HOMES, 1.0))
    ours = _run("global-belief+cover", dict.fromkeys(HOMES, 1.2))
    wpl = _run("wpl+cover", dict.fromkeys(HOMES, 2.0))
    assert "default: **global-belief+cover** stays" in "\n".join(rule_lines(ref + ours + wpl))
    ecost = _run("ecost+cover", dict.fromkeys(HOMES, 1.1))
    text = "\n".join(rule_lines(ref + ours + ecost))
    assert "ecost+cover ÷ global-belief+cover: 0.917 [0.917, 0.917]" in text
    assert "default: changes (lower with a CI excluding 1: ecost+cover)" in text


def test_false_found_above_the_target_asks_for_the_protocols_thresholds() -> None:
    rows = _run("global-belief+cover", dict.fromkeys(HOMES, 1.0))
    assert "the preset's threshold stays" in "\n".join(rule_lines(rows))
    rows[0] = replace(rows[0], success=False, false_found=True)
    assert "runs at 0.95, 0.99, 0.999" in "\n".join(rule_lines(rows))


def test_every_failure_is_listed_with_its_cause() -> None:
    rows = _run("global-belief+cover", dict.fromkeys(HOMES, 1.0)) + _run(
        "dist-oracle-global+cover", dict.fromkeys(HOMES, 1.0)
    )
    rows[0] = replace(
        rows[0],
        success=False,
        false_found=True,
        failure="false found: a false positive Apple at score 0.900 confirmed",
    )
    rows[1] = replace(rows[1], success=False,
                      failure="not found (budget spent): the true target was never reported")  # fmt: skip
    text = "\n".join(failure_lines(rows, lambda r: "camera says"))
    assert "2 failed searches of 48" in text
    assert "| global-belief+cover | false found: a false positive | 1 |" in text
    assert "| global-belief+cover | not found: the target never reported | 1 |" in text
    assert "| false found: a false positive Apple at score 0.900 confirmed | – |" in text
    assert "never reported | camera says |" in text
    assert protocol_lines(rows)[0].startswith("### The perception protocol's measures")
    assert protocol_lines([r for r in rows if not r.strategy.startswith("dist")]) == []


def _output(
    folder: Path, rows: Sequence[Row], perception: str, localisation: str = "perfect"
) -> Path:
    """A bench homes output of made-up rows, run (says its summary.json) with this detector and
    localisation."""
    folder.mkdir()
    write_rows(rows, folder, "homes_trials")
    summary = {
        "perception": {"preset": perception},
        "localisation": {"preset": localisation},
        "camera": "occluding",
    }
    (folder / "summary.json").write_text(json.dumps(summary), encoding="utf-8")
    return folder


def test_bench_belief_divides_by_the_perfect_runs_it_is_given(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ours = _run("global-belief+cover", dict.fromkeys(HOMES, 1.2))
    ref = _run("dist-oracle-global+cover", dict.fromkeys(HOMES, 1.0))
    realistic = _output(tmp_path / "realistic", ours + ref, "realistic")
    halved = [replace(r, path_length=r.path_length / 2) for r in ours + ref]
    perfect = _output(tmp_path / "perfect", halved, "perfect")
    out = tmp_path / "report"
    argv = ["bench", "belief", str(realistic), "--out", str(out), "--no-progress"]
    assert main([*argv, "--perfect", str(perfect)]) == 0
    printed = capsys.readouterr().out
    line = "| global-belief+cover | pooled | 4 | 16 | 1.200 [1.200, 1.200] (**not met**) "
    assert line + "| 2.000 [2.000, 2.000] (**not met**) |" in printed
    assert main(argv) == 0  # without it: no ÷ perfect
    assert line + "| – |" in capsys.readouterr().out
    assert main([*argv, "--perfect", str(realistic)]) == 2
    assert "objsearch: error: not run with perception perfect" in capsys.readouterr().err


def test_the_headline_divides_by_a_baseline_in_a_column_of_its_label() -> None:
    ref = _run("dist-oracle-global+cover", dict.fromkeys(HOMES, 1.0))
    ours = _run("global-belief+cover", dict.fromkeys(HOMES, 1.2))
    shorter = [replace(r, path_length=r.path_length / 1.5) for r in ours]
    table = headline_lines(ours + ref, baseline=("localisation perfect", shorter))
    assert table[2].endswith("| ÷ same strategy, perfect (≤ 1.25) | ÷ same strategy, localisation perfect |")  # fmt: skip
    assert table[3] == "|---|---|---|---|---|---|---|"
    # 1.2 ÷ 1.2/1.5 = 1.5, no target; the reference has no baseline run: –.
    assert "| global-belief+cover | pooled | 4 | 16 | 1.200 [1.200, 1.200] (**not met**) | – | 1.500 [1.500, 1.500] |" in table  # fmt: skip
    assert "| dist-oracle-global+cover | pooled | 4 | 16 | – | – | – |" in table
    # Without one the table is as before: six columns.
    assert headline_lines(ours + ref)[3] == "|---|---|---|---|---|---|"


def test_bench_belief_divides_by_a_baseline_that_differs_in_one_factor(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ours = _run("global-belief+cover", dict.fromkeys(HOMES, 1.2))
    ref = _run("dist-oracle-global+cover", dict.fromkeys(HOMES, 1.0))
    realistic = _output(tmp_path / "realistic", ours + ref, "realistic", "realistic")
    shorter = [replace(r, path_length=r.path_length / 1.5) for r in ours + ref]
    located = _output(tmp_path / "located", shorter, "realistic", "perfect")
    out = tmp_path / "report"
    argv = ["bench", "belief", str(realistic), "--out", str(out), "--no-progress"]
    assert main([*argv, "--baseline", str(located)]) == 0
    printed = capsys.readouterr().out
    # The label, by default, is what the baseline's summary.json says differs.
    assert "| ÷ same strategy, localisation perfect |" in printed
    line = "| global-belief+cover | pooled | 4 | 16 | 1.200 [1.200, 1.200] (**not met**) | – "
    assert line + "| 1.500 [1.500, 1.500] |" in printed
    assert main([*argv, "--baseline", str(located), "--baseline-label", "localiser on"]) == 0
    assert "| ÷ same strategy, localiser on |" in capsys.readouterr().out
    # A label with no baseline, a baseline the same in every recorded factor with no label, and
    # a folder that is no bench homes output are refused.
    assert main([*argv, "--baseline-label", "localiser on"]) == 2
    assert "objsearch: error: --baseline-label names the --baseline runs" in capsys.readouterr().err
    assert main([*argv, "--baseline", str(realistic)]) == 2
    assert "name what differs with --baseline-label" in capsys.readouterr().err
    assert main([*argv, "--baseline", str(tmp_path)]) == 2
    assert "objsearch: error: --baseline: not a bench homes output" in capsys.readouterr().err


def test_bench_belief_labels_a_baseline_whose_new_map_kept_the_frame(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ours = _run("global-belief+cover", dict.fromkeys(HOMES, 1.2))
    ours += _run("dist-oracle-global+cover", dict.fromkeys(HOMES, 1.0))
    moved = _output(tmp_path / "moved", ours, "realistic")
    same = _output(tmp_path / "same", ours, "realistic")
    for folder, frame in ((moved, {"new_map_frame": "moved"}), (same, {})):
        summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
        summary.update({"new_map_day": 2, **frame})
        (folder / "summary.json").write_text(json.dumps(summary), encoding="utf-8")
    argv = ["bench", "belief", str(moved), "--out", str(tmp_path / "r"), "--no-progress"]
    assert main([*argv, "--baseline", str(same)]) == 0
    assert "| ÷ same strategy, new map's frame same |" in capsys.readouterr().out
