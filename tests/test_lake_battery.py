"""The lake-damage battery in CI: one variant of every kind of damage, none may change an answer
silently, crash, or cost a healthy run; and the control without digests shows it would see it."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.lake_battery import KINDS, build_lake, run_battery


@pytest.fixture(scope="module")
def lake(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_lake(tmp_path_factory.mktemp("lake-battery"))


def test_no_damage_changes_an_answer_silently(lake: Path, tmp_path: Path) -> None:
    report = run_battery(lake, tmp_path, per_kind=1, seed=2026)
    assert report.flagged == []
    assert report.ok and report.tried == len(KINDS)
    assert set(report.by_kind) == set(KINDS)
    # Not vacuous: almost every kind was reported (a deleted derived table may be recomputed).
    assert report.counts["clear error"] >= len(KINDS) - 1


def test_without_digests_the_same_battery_sees_silent_changes(lake: Path, tmp_path: Path) -> None:
    # The control: manifests as code before digests wrote them. A valid Parquet file with one
    # value changed, or another run's file copied over, changes the answer without a word.
    kinds = ["valid Parquet, one value changed", "copied from another run"]
    report = run_battery(lake, tmp_path, per_kind=1, seed=2026, kinds=kinds, without_digests=True)
    assert report.counts["silent change"] == 2, report.flagged
