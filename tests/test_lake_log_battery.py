"""The lake-bookkeeping battery in CI: one variant of every kind of edit to a fleet lake's table
log and its runs' ``_run`` files, on the lake and on a compacted copy, through ``query``,
``lake ls``, ``lake verify``, ``lake compact`` and ``lake add``. None may crash a command,
change an answer without a word, or let a compaction make a loss permanent
(``benchmarks/lake_log_damage.py`` tries every target of every kind)."""

from __future__ import annotations

from pathlib import Path

import pytest

from devtools.lake_log_battery import KINDS, build, run_battery


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, Path], Path]:
    return build(tmp_path_factory.mktemp("lake-log-battery"))


def test_no_edit_to_the_log_or_the_runs_records_crashes_changes_an_answer_unsaid_or_is_lost(
    built: tuple[dict[str, Path], Path], tmp_path: Path
) -> None:
    lakes, log = built
    report = run_battery(lakes, log, tmp_path, per_kind=1, seed=2026)
    assert report.tried == 2 * len(KINDS) and set(report.by_kind) == set(KINDS)
    assert report.counts["traceback"] == 0, report.flagged
    assert report.counts["silent change"] == 0, report.flagged
    assert report.counts["loss"] == 0, report.flagged
    # Not vacuous: the kinds that cost rows were reported on both lakes (on the compacted one
    # a commit's lines before the checkpoint are read by no one: unchanged is right there)
    for kind in ("newest commit file deleted", "_run file garbage", "_run file deleted"):
        assert report.by_kind[kind]["clear error"] == 2, (kind, report.by_kind[kind])
