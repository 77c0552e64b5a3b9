"""Checking a log end to end, and the one way past real corruption: an explicit repair.

A writer refuses a damaged log and touches nothing (``CorruptLogError``); only a person running
``objsearch log repair`` changes one, and the repair removes nothing it does not keep: the bytes it
takes out of ``events.log`` go to a quarantine file beside it, named in its report.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from . import _fs
from .errors import CorruptLogError, LogLockedError
from .log import (
    DURABLE_FILE,
    LOCK_FILE,
    LOG_FILE,
    LogMeta,
    LogPosition,
    _Scan,
    quarantine,
    read_durable,
    read_meta,
    write_durable,
)
from .schemas import default_registry


@dataclass(frozen=True, slots=True)
class Verification:
    """A log that read clean from its first record to its last."""

    directory: Path
    stream: str
    run_id: str | None
    format: str
    events: int
    last_seq: int
    durable_seq: int | None  # the high-water mark's seq, if the writer left one
    torn_bytes: int  # an unterminated fragment after the last record (never acknowledged)


@dataclass(frozen=True, slots=True)
class Repair:
    """What :func:`repair_log` changed (nothing, if ``changed`` is False)."""

    directory: Path
    changed: bool
    kept_events: int
    kept_last_seq: int
    removed_bytes: int
    removed_lines: int  # complete lines among the removed bytes
    problem: str | None  # the first problem found, as CorruptLogError described it
    quarantine: Path | None  # where the removed (or replaced) bytes are kept
    missing_seqs: tuple[int, int] | None  # acknowledged seqs (first, last) the file had lost


def verify_log(directory: Path | str) -> Verification:
    """Read every record and check it; raise :class:`CorruptLogError` at the first problem."""
    directory = Path(directory)
    meta = read_meta(directory)
    durable = read_durable(directory)
    scan = _Scan(directory / LOG_FILE, meta, registry=default_registry(), durable=durable)
    events = sum(1 for _ in scan)
    return Verification(
        directory=directory,
        stream=meta.stream,
        run_id=meta.run_id,
        format=meta.format,
        events=events,
        last_seq=scan.last_seq,
        durable_seq=durable.seq if durable is not None else None,
        torn_bytes=scan.torn_tail.length if scan.torn_tail is not None else 0,
    )


def repair_log(directory: Path | str) -> Repair:
    """Make ``directory`` a clean log again, keeping every byte it takes out.

    Under the writer's lock: a log whose every line ends in CR LF is converted back (the
    original kept as ``events.log.crlf``) if that makes it clean; otherwise everything from the
    first damaged record on is moved to ``events.log.repair-<offset>`` and the log keeps the clean
    prefix. The high-water mark is rewritten to the new end (a damaged one is kept aside), and
    acknowledged records the file had already lost are reported, since nothing can bring them
    back. Raises :class:`LogLockedError` if a writer has the log open.
    """
    directory = Path(directory)
    meta = read_meta(directory)
    path = directory / LOG_FILE
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
    try:
        lock_fd = _fs.try_lock(directory / LOCK_FILE) if _fs.flock_nb(fd) else None
        if lock_fd is None:
            raise LogLockedError(
                f"event log {directory} is open for writing; stop its writer first"
            )
        try:
            return _repair_locked(directory, meta, fd)
        finally:
            os.close(lock_fd)
    finally:
        os.close(fd)


def _repair_locked(directory: Path, meta: LogMeta, fd: int) -> Repair:
    path = directory / LOG_FILE
    data = path.read_bytes()
    try:
        durable = read_durable(directory)
    except CorruptLogError:
        quarantine(directory, "durable-damaged", (directory / DURABLE_FILE).read_bytes())
        durable = None
    problem, mark, events = _clean_prefix(path, meta)
    end, last_seq = mark.offset, mark.seq
    kept: Path | None = None
    if problem is not None and _is_crlf(data):
        converted = data.replace(b"\r\n", b"\n")
        candidate = directory / f"{LOG_FILE}.crlf-candidate"
        candidate.write_bytes(converted)
        try:
            result = _clean_prefix(candidate, meta)
        finally:
            candidate.unlink()
        if result[0] is None and result[1].offset == len(converted):
            kept = quarantine(directory, "crlf", data)
            _fs.write_atomic(path, converted)
            _, mark, events = result
            write_durable(directory, mark)
            return Repair(directory, True, events, mark.seq, 0, 0, problem, kept, None)
    removed = data[end:]
    if removed:
        kept = quarantine(directory, f"repair-{end}", removed)
        os.ftruncate(fd, end)
        os.fsync(fd)
    missing = None
    if durable is not None and durable.seq > last_seq:
        missing = (last_seq + 1, durable.seq)
    changed = bool(removed) or (durable != mark and last_seq > 0)
    if changed and last_seq > 0:
        write_durable(directory, mark)
    elif last_seq == 0 and durable is not None:
        changed = True
        (directory / DURABLE_FILE).unlink()
        _fs.fsync_dir(directory)
    return Repair(
        directory=directory,
        changed=changed,
        kept_events=events,
        kept_last_seq=last_seq,
        removed_bytes=len(removed),
        removed_lines=removed.count(b"\n"),
        problem=problem,
        quarantine=kept,
        missing_seqs=missing,
    )


def _clean_prefix(path: Path, meta: LogMeta) -> tuple[str | None, LogPosition, int]:
    """(first problem, where the longest clean prefix ends, its events)."""
    scan = _Scan(path, meta, registry=default_registry())
    events = 0
    problem = None
    try:
        for _ in scan:
            events += 1
    except CorruptLogError as exc:
        problem = str(exc)
    if problem is None and scan.torn_tail is not None:
        problem = f"unterminated fragment of {scan.torn_tail.length} byte(s) at the end"
    at = scan.at
    return problem, LogPosition(at.seq, at.offset, at.checksum, at.line, at.time_ns), events


def _is_crlf(data: bytes) -> bool:
    return data.count(b"\n") > 0 and data.count(b"\r\n") == data.count(b"\n")
