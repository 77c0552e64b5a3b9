"""End to end: a tiny ``bench paper`` and ``bench homes`` write their tables and JSON summaries."""

from __future__ import annotations

import json
import re
from pathlib import Path

import polars as pl
import pytest

from objsearch.cli import main
from objsearch.experiments.metrics import spl_term, summarise
from objsearch.experiments.runner import Job, Row, run_job


def test_tiny_bench_paper_writes_outputs_and_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "paper"
    argv = ["bench", "paper", "--out", str(out), "--targets", "Apple,Vase", "--scenes", "1"]
    argv += [
        "--sdp-seeds",
        "2",
        "--strategies",
        "sdp,wpl,wpl-neg-decay",
        "--workers",
        "1",
        "--format",
        "json",
    ]
    assert main(argv) == 0
    headline = json.loads(capsys.readouterr().out)
    t1 = headline["strategies"]["table1"]
    assert set(t1) == {"sdp", "wpl"}
    assert set(headline["strategies"]["longterm"]) == {
        "wpl/none",
        "wpl/targets",
        "wpl/all",
        "wpl-neg-decay/all",
    }
    for metrics in t1.values():
        assert set(metrics) == {"mean_path_length", "success_rate", "spl", "oracle_ratio"}
        assert metrics["success_rate"] == 1.0 and 0 < metrics["spl"] <= 1
        assert metrics["oracle_ratio"] >= 1.0
    frame = pl.read_parquet(out / "paper_trials.parquet")
    # Table I: (2 SDP seeds + WPL) × 2 targets × 8 starts; long-term: 4 runs × 2 × 8.
    assert frame.height == 3 * 16 + 4 * 16
    assert pl.read_csv(out / "paper_trials.csv").height == frame.height
    summary = json.loads((out / "summary.json").read_text())
    assert summary["table1"]["sdp"]["seeds"] == [0, 1]
    assert summary["table1"]["wpl"]["paper"]["avg"] == 10.04
    assert "Table I" in (out / "tables.txt").read_text()
    # --format json prints the figures the text prints (the paper's metric, per target and per
    # scene), rounded as there; the headline metrics to 4 decimals.
    wpl = headline["table1"]["wpl"]
    assert set(wpl["per_target_m"]) == {"Apple", "Vase"} and wpl["paper_m"]["avg"] == 10.04
    assert wpl["path_to_discovery_m"] == round(
        summary["table1"]["wpl"]["mean_path_to_discovery"], 2
    )
    updates = headline["longterm"]["wpl/all"]
    assert set(updates["per_scene_m"]) == {"1"} and updates["change_vs_wpl_none_pct"] is not None
    assert headline["longterm"]["wpl/none"]["change_vs_wpl_none_pct"] == 0.0

    def floats(value: object) -> list[float]:
        if isinstance(value, float):
            return [value]
        if isinstance(value, dict):
            return [f for v in value.values() for f in floats(v)]
        return [f for v in value for f in floats(v)] if isinstance(value, list) else []

    assert all(f == round(f, 4) for f in floats(headline))
    assert any(f != round(f, 4) for f in floats(summary["strategies"]))  # summary.json: all


def test_a_bench_in_a_pipe_prints_a_line_per_tenth_of_its_searches(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Where no bar is drawn (stderr a pipe, as under capsys) a bench run said nothing until it
    ended: an hour for the README's bench paper without --strategies (issue 47)."""
    argv = ["bench", "paper", "--out", str(tmp_path / "p"), "--strategies", "wpl"]
    argv += ["--targets", "Apple,Cup", "--scenes", "1,2", "--workers", "1"]
    assert main(argv) == 0
    lines = capsys.readouterr().err.splitlines()
    assert lines and "\r" not in "".join(lines)
    pattern = re.compile(r"bench paper: (\d+) of 112 searches \(\d+ s\)")  # 16 + 3 x 32
    done = [int(m[1]) for m in map(pattern.fullmatch, lines) if m]
    assert len(done) == len(lines) <= 10, lines
    assert done == sorted(done) and done[-1] == 112
    assert main([*argv, "--no-progress"]) == 0
    assert capsys.readouterr().err == ""


def test_same_seed_same_results(tmp_path: Path) -> None:
    job = Job("table1", "paper", "table1", "sdp", "none", seed=5, targets=("Cup",))
    assert run_job(job) == run_job(job)
    other = run_job(Job("table1", "paper", "table1", "sdp", "none", seed=6, targets=("Cup",)))
    assert [r.seed for r in other] == [6] * 8


def test_tiny_bench_homes_on_a_walked_house(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [
        "bench",
        "homes",
        "--out",
        str(tmp_path),
        "--homes",
        "procthor-00",
        "--scenes-per-schedule",
        "1",
    ]
    argv += ["--strategies", "wpl,epl", "--workers", "1", "--format", "json"]
    assert main(argv) == 0
    headline = json.loads(capsys.readouterr().out)
    assert set(headline["strategies"]) == {"wpl", "epl", "wpl/none"}
    assert (tmp_path / "homes_trials.parquet").is_file()


def test_unknown_home_and_strategy_are_clear_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["bench", "homes", "--out", str(tmp_path), "--homes", "nowhere"]) == 2
    assert "unknown home(s) nowhere" in capsys.readouterr().err
    assert main(["bench", "paper", "--out", str(tmp_path), "--strategies", "magic"]) == 2
    assert "unknown strategy 'magic'" in capsys.readouterr().err


def test_spl_and_oracle_ratio_by_hand() -> None:
    def row(success: bool, path: float, oracle: float) -> Row:
        return Row("x", "h", "p", "s", "none", 0, 1, "Cup", "a", success, path, oracle, "t")

    rows = [row(True, 4.0, 2.0), row(True, 0.0, 0.0), row(False, 6.0, 1.0)]
    assert [spl_term(r) for r in rows] == [0.5, 1.0, 0.0]
    s = summarise(rows)
    assert s["spl"] == pytest.approx(0.5) and s["success_rate"] == pytest.approx(2 / 3)
    assert s["oracle_ratio"] == pytest.approx(10.0 / 3.0)


def test_bench_homes_runs_every_search_from_the_prior_it_is_given(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from objsearch.agent.session import DEFAULT_PRIOR
    from objsearch.experiments.homes import homes_jobs

    argv = ["bench", "homes", "--out", str(tmp_path), "--homes", "procthor-00"]
    argv += ["--scenes-per-schedule", "1", "--starts-per-scene", "1", "--strategies"]
    argv += ["global-belief", "--workers", "1", "--format", "json", "--prior", "vg-hoz-masked"]
    assert main(argv) == 0
    capsys.readouterr()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["prior"] == "vg-hoz-masked" and "--prior vg-hoz-masked" in summary["command"]
    # Every job, the no-update wpl twin too, carries it to its run spec (runner.run_job).
    jobs = homes_jobs(["procthor-00"], ["global-belief", "wpl"], 1, prior="vg-hoz-masked")
    assert len(jobs) == 3 and {j.prior for j in jobs} == {"vg-hoz-masked"}
    assert {j.prior for j in homes_jobs(["procthor-00"], ["wpl"], 1)} == {DEFAULT_PRIOR}
