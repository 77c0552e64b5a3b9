"""The optional-fields battery in CI (devtools/lake_fields_battery.py): every optional field of
the latest version of every schema made null, and some made absent, through ``lake add`` → read
back → ``replay`` / ``where``. A null field must come back as the log has it (before the run
digest hashed values, a null ``task_started.clock`` or ``detection.support`` made the lake refuse
the run: a loss); an absent one must be a clear error of ``lake add`` (the table would read it
back as null, or not take it at all). ``python benchmarks/lake_fields.py`` runs every variant of
every version."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pytest

from devtools.lake_fields_battery import COLUMNS, Variant, run_battery, variants
from objsearch.agent.catalogue import STORE


def _suite(every: list[Variant]) -> Sequence[Variant]:
    """The null variants of each type's latest version, and the absent ones of task_started."""
    latest = [v for v in every if v.version == STORE.registry.latest_version(v.event_type)]
    return [v for v in latest if v.how == "null" or v.event_type == "task_started"]


def test_the_schemas_have_optional_fields_to_try() -> None:
    names = {v.name for v in variants(STORE)}
    assert "task_started v2 clock null" in names
    assert "task_started v2 clock absent" in names
    assert "objects_detected v1 detections[0].position null" in names


@pytest.mark.slow  # ~26 s: a lake add, two replays and two wheres a variant
def test_no_optional_field_is_lost_changed_or_crashes_through_the_lake(tmp_path: Path) -> None:
    report = run_battery(tmp_path, choose=_suite)
    assert report.tried >= 10, report.by_type
    assert sum(report.counts[c] for c in COLUMNS) == report.tried
    assert report.ok, report.flagged
    verdicts = {r.variant.name: r.verdict for r in report.results}
    # the repro of issue 43 item 1: a search's run, its clock null, reads back as its log
    assert verdicts["task_started v2 clock null"] == "unchanged"
    assert verdicts["task_started v2 clock absent"] == "clear error"
    # Every null reads back as it was written; one is refused before the lake sees it: a
    # record_quarantined whose quarantine is null is, to read_log, a damaged record.
    refused_by_the_log = {"record_quarantined v1 quarantine null"}
    assert {
        r.variant.name: r.verdict
        for r in report.results
        if r.variant.how == "null" and r.verdict != "unchanged"
    } == dict.fromkeys(refused_by_the_log, "clear error")
