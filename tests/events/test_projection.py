from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import (
    Event,
    EventLog,
    Projection,
    ProjectionError,
    deterministic_event_id,
    fold,
    read_log,
)


class Reasons:
    """A minimal projection: the list of search_failed reasons seen so far."""

    def __init__(self, last_seq: int = 0, reasons: list[str] | None = None) -> None:
        self._last_seq = last_seq
        self._reasons = list(reasons or [])

    @property
    def last_seq(self) -> int:
        return self._last_seq

    @property
    def state(self) -> list[str]:
        return self._reasons

    def apply(self, event: Event) -> None:
        self._reasons.append(event.payload["reason"])
        self._last_seq = event.seq


class Forgetful(Reasons):
    def apply(self, event: Event) -> None:
        self._reasons.append(event.payload["reason"])  # forgets to advance last_seq


def event(seq: int) -> Event:
    return Event(
        event_id=deterministic_event_id("s", seq),
        stream="s",
        seq=seq,
        time_ns=seq,
        recorded_at_ns=0,
        type="search_failed",
        version=1,
        task_id=None,
        payload={"reason": f"r{seq}"},
    )


def test_fold_applies_events_in_order_and_returns_the_projection() -> None:
    projection = Reasons()
    result = fold([event(1), event(2), event(3)], projection)
    assert result is projection
    assert result.state == ["r1", "r2", "r3"]
    assert result.last_seq == 3


def test_projection_protocol_is_satisfied_structurally() -> None:
    projection: Projection[list[str]] = Reasons()
    assert fold([event(1)], projection).state == ["r1"]


def test_fold_over_a_log(tmp_path: Path) -> None:
    with EventLog.open(tmp_path, "s", store=STORE) as log:
        for i in range(5):
            log.append("search_failed", {"reason": f"r{i + 1}"}, time_ns=i)
    assert fold(read_log(tmp_path, store=STORE), Reasons()).state == ["r1", "r2", "r3", "r4", "r5"]


def test_until_seq_gives_the_state_as_of_that_event_without_consuming_more() -> None:
    events = iter([event(1), event(2), event(3), event(4)])
    projection = fold(events, Reasons(), until_seq=2)
    assert projection.state == ["r1", "r2"]
    assert next(events).seq == 3  # the fold stopped right after seq 2


def test_resume_skips_events_already_applied() -> None:
    snapshot = Reasons(last_seq=2, reasons=["r1", "r2"])
    assert fold([event(1), event(2), event(3)], snapshot).state == ["r1", "r2", "r3"]


def test_a_gap_is_refused() -> None:
    with pytest.raises(
        ProjectionError, match=r"at seq 1 and cannot apply seq 3 .*2\.\.2 are missing"
    ):
        fold([event(1), event(3)], Reasons())


def test_apply_must_advance_last_seq() -> None:
    with pytest.raises(ProjectionError, match=r"Forgetful.apply\(seq 1\) left last_seq at 0"):
        fold([event(1)], Forgetful())


def test_cannot_fold_backwards() -> None:
    with pytest.raises(
        ProjectionError, match="already at seq 3; it cannot be folded back to seq 2"
    ):
        fold([], Reasons(last_seq=3), until_seq=2)
    assert fold([event(1)], Reasons(last_seq=3), until_seq=3).last_seq == 3
