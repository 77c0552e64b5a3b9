"""The lake-damage battery in CI: one variant of every kind of damage to a fleet lake's data files
and its table's log. None may crash a command; what costs a healthy file or changes an answer
without a word is held to the kinds docs/analytics.md names as the lake's known gaps, all in the
table's log (a garbled name or statistic in a commit file; a deleted newest commit file is refused
since the lake records the version it last committed, tests/test_lake_log_battery.py): every data
file is content-addressed and a query checks its hash, so no damage to one may go unsaid. The variants
differ from build to build (the data files' names carry random tokens), so the test allows those
kinds, not counts."""

from __future__ import annotations

from pathlib import Path

import pytest

from devtools.lake_battery import KINDS, build_lake, run_battery


@pytest.fixture(scope="module")
def lake(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_lake(tmp_path_factory.mktemp("lake-battery"))


def test_no_damage_crashes_a_command_and_silent_changes_keep_to_the_known_gaps(
    lake: Path, tmp_path: Path
) -> None:
    report = run_battery(lake, tmp_path, per_kind=1, seed=2026)
    assert report.tried == len(KINDS) and set(report.by_kind) == set(KINDS)
    assert report.counts["traceback"] == 0, report.flagged
    # A bit flip in a commit file can garble a data file's name: that healthy file is then left
    # out, with a warning naming it (docs/analytics.md); no other kind may cost a healthy file.
    lost = {k for k, row in report.by_kind.items() if row["loss"]}
    assert lost <= {"commit file bit flip"}, report.flagged
    # Not vacuous: most kinds were reported (cuts, deleted files, a commit file cut or deleted).
    assert report.counts["clear error"] >= len(KINDS) // 2, report.by_kind
    # The known gap, held to its kind: only a bit flip in the table's log may change an answer
    # silently (a commit file deleted is refused: the newest by the lake's record of its
    # version, another by delta-rs); a data file's damage is left out and named, whatever it is
    # (its hash is in its name).
    silent = {k for k, row in report.by_kind.items() if row["silent change"]}
    assert silent <= {"commit file bit flip"}, report.flagged
