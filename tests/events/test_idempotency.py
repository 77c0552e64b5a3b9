"""Appends are idempotent by event id, and may state the seq they expect the log to end at."""

from __future__ import annotations

import uuid
from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import (
    DuplicateEventError,
    EventLog,
    WrongExpectedSeqError,
    deterministic_event_id,
    read_log,
)

IDS = [str(uuid.UUID(int=i)) for i in range(1, 6)]


def import_events(log: EventLog, n: int) -> None:
    for i in range(n):
        log.append("search_failed", {"reason": f"r{i}"}, time_ns=i, event_id=IDS[i])


def test_re_running_an_import_never_duplicates(tmp_path: Path) -> None:
    with EventLog.open(tmp_path, "s", store=STORE) as log:
        import_events(log, 3)
    size = (tmp_path / "events.log").stat().st_size
    with EventLog.open(
        tmp_path, "s", store=STORE
    ) as log:  # a new writer learns the ids from the file
        import_events(log, 3)
        assert log.last_seq == 3
    assert (tmp_path / "events.log").stat().st_size == size
    with EventLog.open(
        tmp_path, "s", store=STORE
    ) as log:  # an interrupted import resumes where it stopped
        import_events(log, 5)
    assert [e.event_id for e in read_log(tmp_path, store=STORE)] == IDS


def test_a_duplicate_returns_the_stored_event(tmp_path: Path) -> None:
    with EventLog.open(tmp_path, "s", wall_clock=lambda: 7, store=STORE) as log:
        first = log.append("search_failed", {"reason": "x"}, time_ns=1, event_id=IDS[0])
        log.append("search_failed", {"reason": "y"}, time_ns=2)
        with log.batch():  # also inside a batch, before the fsync
            again = log.append("search_failed", {"reason": "x"}, time_ns=1, event_id=IDS[0])
            in_batch = log.append("search_failed", {"reason": "z"}, time_ns=3, event_id=IDS[1])
            assert log.append("search_failed", {"reason": "z"}, time_ns=3, event_id=IDS[1]) == (
                in_batch
            )
    assert again == first
    assert [e.seq for e in read_log(tmp_path, store=STORE)] == [1, 2, 3]


@pytest.mark.parametrize(
    ("change", "named"),
    [
        ({"payload": {"reason": "other"}}, "payload"),
        ({"time_ns": 99}, "time_ns"),
        ({"task_id": "t-2"}, "task_id"),
        (
            {"type": "task_ended", "payload": {"target": "Cup", "success": True, "path_length": 1}},
            "type",
        ),
    ],
)
def test_the_same_id_for_another_fact_is_refused(
    tmp_path: Path, change: dict[str, object], named: str
) -> None:
    args: dict[str, object] = {
        "type": "search_failed",
        "payload": {"reason": "x"},
        "time_ns": 1,
        "task_id": "t-1",
    }
    with EventLog.open(tmp_path, "s", store=STORE) as log:
        log.append(event_id=IDS[0], **args)  # type: ignore[arg-type]
        before = (tmp_path / "events.log").read_bytes()
        with pytest.raises(DuplicateEventError, match=f"at seq 1 with a different .*{named}"):
            log.append(event_id=IDS[0], **(args | change))  # type: ignore[arg-type]
        assert log.last_seq == 1
    assert (tmp_path / "events.log").read_bytes() == before


def test_an_explicit_id_that_takes_a_future_default_id_is_caught(tmp_path: Path) -> None:
    with EventLog.open(tmp_path, "s", store=STORE) as log:
        assert log.run_id is not None
        log.append(
            "search_failed",
            {"reason": "a"},
            time_ns=0,
            event_id=deterministic_event_id(log.run_id, 2),
        )
        with pytest.raises(DuplicateEventError, match="default id"):
            log.append("search_failed", {"reason": "b"}, time_ns=0)
        assert log.last_seq == 1


def test_expected_last_seq(tmp_path: Path) -> None:
    with EventLog.open(tmp_path, "s", store=STORE) as log:
        log.append("search_failed", {"reason": "a"}, time_ns=0, expected_last_seq=0)
        log.append(
            "search_failed", {"reason": "b"}, time_ns=0, event_id=IDS[1], expected_last_seq=1
        )
        with pytest.raises(WrongExpectedSeqError, match="ends at seq 2, not at the expected seq 1"):
            log.append("search_failed", {"reason": "c"}, time_ns=0, expected_last_seq=1)
        # A retry of an append that did land succeeds although the expectation is now stale.
        log.append(
            "search_failed", {"reason": "b"}, time_ns=0, event_id=IDS[1], expected_last_seq=1
        )
        assert log.last_seq == 2
