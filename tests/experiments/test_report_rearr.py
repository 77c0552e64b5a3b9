"""``bench homes --schedules rearr,stats`` and the rearrangement results page generated from it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from objsearch.cli import main


def test_tiny_rearr_run_and_its_generated_page(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    argv = [
        "bench",
        "homes",
        "--out",
        str(run),
        "--homes",
        "ithor-09",
        "--scenes-per-schedule",
        "1",
    ]
    argv += [
        "--schedules",
        "rearr,stats",
        "--strategies",
        "wpl",
        "--workers",
        "1",
        "--format",
        "json",
    ]
    assert main(argv) == 0
    capsys.readouterr()
    summary = json.loads((run / "summary.json").read_text())
    assert summary["schedules"] == ["rearr", "stats"]
    assert set(summary["by_schedule"]) == {"rearr", "stats"}
    page = tmp_path / "docs" / "results-rearrangement.md"
    page.parent.mkdir()
    argv = ["bench", "report", "--rearr", str(run), "--out", str(tmp_path / "docs" / "results.md")]
    argv += ["--paper", str(tmp_path / "none"), "--evaluation", str(tmp_path / "none")]
    assert main(argv) == 0
    said = capsys.readouterr().out
    assert f"wrote {page}" in said and "kept" in said  # no paper/homes runs: results.md untouched
    assert not (tmp_path / "docs" / "results.md").exists()
    text = page.read_text()
    assert "--schedules rearr,stats --seeds 1 --scenes-per-schedule 1 --strategies wpl" in text
    assert "rearr schedules (rearr-<seed>, seeds [0])" in text
    assert "- ithor-09: Apple, Pillow, Vase" in text  # fallback classes are reported


def test_report_needs_a_rearr_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "report", "--rearr", str(tmp_path)]) == 2
    assert "no bench summary" in capsys.readouterr().err
