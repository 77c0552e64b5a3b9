"""The log fuzzer in CI: a few thousand seeded mutations, none may lose or change a fact."""

from __future__ import annotations

import pytest

from devtools.logfuzz import MUTATIONS, run_log_fuzz, run_repair_fuzz, run_snapshot_fuzz

#: Each test runs a command or a fuzzer thousands of times: tens of seconds.
pytestmark = pytest.mark.slow


def test_no_mutation_is_silently_accepted_or_crashes_the_writer() -> None:
    report = run_log_fuzz(2000, seed=20261201)
    assert report.failures == []
    assert report.ok, report.summary()
    assert report.tried == 2000
    # Every kind of damage was tried, and most of it refused: the harness is not vacuous.
    assert {key.split(":")[0] for key in report.by_mutation} == {m.__name__ for m in MUTATIONS}
    assert report.refused > 0.8 * report.tried
    assert report.torn_kept > 0 and report.unchanged > 0


def test_a_sealed_restart_refuses_every_damage_a_full_check_refuses() -> None:
    full = run_log_fuzz(600, seed=20261202)
    sealed = run_log_fuzz(600, seed=20261202, verify="sealed")
    assert sealed.failures == [], sealed.failures[:3]
    assert (sealed.refused, sealed.unchanged, sealed.torn_kept) == (
        full.refused,
        full.unchanged,
        full.torn_kept,
    )


def test_repair_takes_out_only_what_it_must_and_loses_nothing() -> None:
    report = run_repair_fuzz(400, seed=20261203, events=60)
    assert report.failures == [], report.failures[:3]
    assert report.ok, report.summary()
    assert {key.split(":")[0] for key in report.by_mutation} == {m.__name__ for m in MUTATIONS}
    assert report.repaired > 0.6 * report.tried
    # No damage here costs an intact record: each is found by its witnesses (its chained
    # checksum, its id), swapped lines and re-checksummed edits included (they cost records
    # before events/repair_plan.py).
    assert report.moved_by_mutation == {}
    assert sum(report.intact_moved_out) == 0


def test_a_damaged_snapshot_is_never_believed() -> None:
    report = run_snapshot_fuzz(120, seed=20261204)
    assert report.failures == [] and report.ok, report.summary()
    assert report.rebuilt > 0.5 * report.tried and report.unchanged > 0
