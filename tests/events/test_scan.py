"""A verifying scan checks the event ids a batch at a time (events/scan.py): the first bad
record is still the one named, and named as a reading scan names it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import CorruptLogError, EventLog, read_log
from objsearch.events.repair import verify_log
from objsearch.events.scan import _ID_BATCH

from .rechain import rechain

EVENTS = _ID_BATCH + 600  # two batches


def _log(directory: Path) -> None:
    with EventLog.open(directory, "s", store=STORE) as log, log.batch():
        for i in range(EVENTS):
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=i)
    # No seals for the verifier to check first: the records alone decide.
    (directory / "durable.json").unlink()


def _upper_id(record: dict[str, Any]) -> None:
    record["event_id"] = record["event_id"].upper()


def _both_errors(directory: Path) -> tuple[CorruptLogError, CorruptLogError]:
    with pytest.raises(CorruptLogError) as verified:
        verify_log(directory, store=STORE)
    with pytest.raises(CorruptLogError) as read:
        list(read_log(directory, store=STORE))
    return verified.value, read.value


@pytest.mark.parametrize("bad", [1, 700, _ID_BATCH, _ID_BATCH + 1, EVENTS])
def test_a_non_canonical_id_is_named_at_its_line(tmp_path: Path, bad: int) -> None:
    _log(tmp_path)
    rechain(tmp_path, {bad: _upper_id})
    verified, read = _both_errors(tmp_path)
    assert verified.line == read.line == bad
    assert str(verified) == str(read)
    assert "event_id" in str(verified) and "not a canonical UUID" in str(verified)


def test_a_bad_id_before_another_fault_in_its_batch_is_the_one_named(tmp_path: Path) -> None:
    def gap(record: dict[str, Any]) -> None:
        record["seq"] += 1

    _log(tmp_path)
    rechain(tmp_path, {300: _upper_id, 305: gap})
    verified, read = _both_errors(tmp_path)
    assert verified.line == read.line == 300
    assert str(verified) == str(read)


def test_a_bad_id_after_a_record_the_slow_path_read_is_named_at_its_line(tmp_path: Path) -> None:
    """A record_quarantined always takes the slow path, which checks the ids read before it:
    the batch then starts again at that record, not where the scan began."""

    def quarantined(record: dict[str, Any]) -> None:
        record["type"], record["version"] = "record_quarantined", 1
        record["payload"] = {
            "reason": "test",
            "quarantine": None,
            "offset": 0,
            "length": 0,
            "chain": None,
        }

    # Past the first _ID_BATCH lines: read again from where the scan began, the batch would not
    # reach it.
    bad = _ID_BATCH + 100
    _log(tmp_path)
    rechain(tmp_path, {200: quarantined, bad: _upper_id})
    verified, read = _both_errors(tmp_path)
    assert verified.line == read.line == bad
    assert str(verified) == str(read)


def test_a_payload_that_is_not_an_object_is_named_at_its_line(tmp_path: Path) -> None:
    def scalar(record: dict[str, Any]) -> None:
        record["payload"] = 5

    _log(tmp_path)
    rechain(tmp_path, {900: scalar})
    verified, read = _both_errors(tmp_path)
    assert verified.line == read.line == 900
    assert str(verified) == str(read)
    assert "payload" in str(verified)


def test_an_intact_log_of_two_batches_verifies(tmp_path: Path) -> None:
    _log(tmp_path)
    rechain(tmp_path, {})
    assert verify_log(tmp_path, store=STORE).events == EVENTS
