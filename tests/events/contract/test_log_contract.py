"""The log contract (:mod:`.log_contract`) run against the JSON-lines event log."""

from __future__ import annotations

import os
from pathlib import Path

from objsearch.agent.catalogue import STORE
from objsearch.events import CorruptLogError, Event, EventLog, read_log

from .log_contract import RUN, LogContract


def _lines(directory: Path) -> list[bytes]:
    return (directory / "events.log").read_bytes().splitlines(keepends=True)


class TestJsonLinesLog(LogContract):
    damage_message = "checksum mismatch"

    def open(self, directory: Path, stream: str = "run-1") -> EventLog:
        return EventLog.open(directory, stream, wall_clock=lambda: 42, run_id=RUN, store=STORE)

    def read(self, directory: Path) -> list[Event]:
        return list(read_log(directory, store=STORE))

    def abandon(self, log: EventLog) -> None:
        os.close(log._fd)
        os.close(log._lock_fd)
        log._closed = True

    def tear(self, directory: Path) -> None:
        data = (directory / "events.log").read_bytes()
        (directory / "events.log").write_bytes(data[: len(data) - len(_lines(directory)[-1]) // 2])

    def damage(self, directory: Path, seq: int) -> None:
        lines = _lines(directory)
        lines[seq - 1] = lines[seq - 1][:2] + lines[seq - 1][2:3].upper() + lines[seq - 1][3:]
        (directory / "events.log").write_bytes(b"".join(lines))

    def stored(self, directory: Path) -> object:
        return {p.name: p.read_bytes() for p in sorted(directory.iterdir()) if p.is_file()}

    def located(self, error: CorruptLogError, directory: Path, seq: int) -> None:
        offset = sum(len(x) for x in _lines(directory)[: seq - 1])
        assert (error.line, error.offset) == (seq, offset)
        assert f"line {seq} (byte offset {offset})" in str(error)
        assert str(directory / "events.log") in str(error)
