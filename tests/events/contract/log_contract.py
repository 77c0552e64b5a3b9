"""What every event log passes (today one backend: the JSON-lines log of
:mod:`objsearch.events.log`; ``test_log_contract.py`` runs it). :class:`LogContract` is the
abstract test case: appends read back equal and in order, a reopened log continues, what was
acknowledged survives a writer that died, a write cut short by the death is a torn tail (cut,
the rest kept), a damaged record anywhere is corruption (never skipped, nothing changed), one
writer at a time. How a backend's bytes are torn or damaged, and where it says the damage is,
are its hooks."""

from __future__ import annotations

import os
import warnings
from abc import ABC, abstractmethod
from pathlib import Path
from typing import ClassVar

import pytest

from objsearch.events import (
    CorruptLogError,
    Event,
    EventLog,
    LogLockedError,
    TornTailWarning,
    deterministic_event_id,
)

from ..payloads import EXAMPLES

RUN = "00000000-0000-4000-8000-0000000000aa"


class LogContract(ABC):
    #: What a backend's corruption error says of a damaged record.
    damage_message: ClassVar[str]

    @abstractmethod
    def open(self, directory: Path, stream: str = "run-1") -> EventLog:
        """A writer of ``directory`` (run id :data:`RUN`, ``recorded_at_ns`` 42)."""

    @abstractmethod
    def read(self, directory: Path) -> list[Event]: ...

    @abstractmethod
    def abandon(self, log: EventLog) -> None:
        """What a killed writer leaves: its descriptors closed by the kernel, nothing else."""

    @abstractmethod
    def tear(self, directory: Path) -> None:
        """Cut the last record short, as a write interrupted by a kill leaves it."""

    @abstractmethod
    def damage(self, directory: Path, seq: int) -> None:
        """Change a byte of the record at ``seq`` (its size unchanged)."""

    @abstractmethod
    def stored(self, directory: Path) -> object:
        """Everything the backend holds of the log (to show nothing changed)."""

    def located(self, error: CorruptLogError, directory: Path, seq: int) -> None:  # noqa: B027
        """Check that ``error`` says where the damaged record ``seq`` is (a backend's hook)."""

    def write(self, directory: Path, n: int, *, died: bool = False) -> list[Event]:
        log = self.open(directory)
        first = log.last_seq
        events = [
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=i)
            for i in range(first, first + n)
        ]
        if died:
            self.abandon(log)
        else:
            log.close()
        return events

    def test_append_then_read_round_trips_every_event_type(self, tmp_path: Path) -> None:
        with self.open(tmp_path / "log") as log:
            written = [
                log.append(t, p, time_ns=10 * i, task_id="t1")
                for i, (t, p) in enumerate(EXAMPLES.items())
            ]
            assert log.last_seq == len(EXAMPLES)
        read = self.read(tmp_path / "log")
        assert read == written
        assert [e.seq for e in read] == list(range(1, len(EXAMPLES) + 1))
        assert read[0].event_id == deterministic_event_id(RUN, 1)
        assert read[0].recorded_at_ns == 42

    def test_reopening_continues_the_sequence(self, tmp_path: Path) -> None:
        self.write(tmp_path, 3)
        with self.open(tmp_path) as log:
            assert log.last_seq == 3
            event = log.append("search_failed", {"reason": "again"}, time_ns=9)
        assert event.seq == 4
        assert event.event_id == deterministic_event_id(RUN, 4)
        assert [e.seq for e in self.read(tmp_path)] == [1, 2, 3, 4]

    def test_what_was_acknowledged_survives_a_writer_that_died(self, tmp_path: Path) -> None:
        acknowledged = self.write(tmp_path, 2) + self.write(tmp_path, 3, died=True)
        assert self.read(tmp_path) == acknowledged
        with self.open(tmp_path) as log:
            assert log.last_seq == 5 and log.torn_tail is None

    def test_a_write_the_writers_death_cut_short_is_a_torn_tail(self, tmp_path: Path) -> None:
        kept = self.write(tmp_path, 2)
        self.write(tmp_path, 1, died=True)
        self.tear(tmp_path)
        before = self.stored(tmp_path)
        with pytest.warns(TornTailWarning):
            assert self.read(tmp_path) == kept
        assert self.stored(tmp_path) == before  # a reader changes nothing
        with pytest.warns(TornTailWarning), self.open(tmp_path) as log:
            assert log.last_seq == 2 and log.torn_tail is not None
            assert log.append("search_failed", {"reason": "after"}, time_ns=5).seq == 3
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # cut by the writer: no longer a torn tail
            assert [e.seq for e in self.read(tmp_path)] == [1, 2, 3]

    @pytest.mark.parametrize(
        ("closed", "died", "seq"),
        [(5, 0, 3), (4, 1, 5)],
        ids=["in-the-middle", "last-record-of-a-dead-writer"],
    )
    def test_a_damaged_record_is_corruption_not_a_torn_tail(
        self, tmp_path: Path, closed: int, died: int, seq: int
    ) -> None:
        self.write(tmp_path, closed)
        if died:
            self.write(tmp_path, died, died=True)
        self.damage(tmp_path, seq)
        before = self.stored(tmp_path)
        with pytest.raises(CorruptLogError, match=self.damage_message) as info:
            self.read(tmp_path)
        self.located(info.value, tmp_path, seq)
        with pytest.raises(CorruptLogError, match=self.damage_message):
            self.open(tmp_path)
        assert self.stored(tmp_path) == before  # nothing cut, nothing set aside
        with pytest.raises(CorruptLogError):  # not LogLockedError: the failed open let go
            self.open(tmp_path)

    def test_a_second_writer_is_locked_out_until_the_first_closes(self, tmp_path: Path) -> None:
        first = self.open(tmp_path)
        with pytest.raises(LogLockedError, match=f"already open for writing .*pid {os.getpid()}"):
            self.open(tmp_path)
        first.close()
        with self.open(tmp_path) as second:
            assert second.append("search_failed", {"reason": "x"}, time_ns=0).seq == 1
