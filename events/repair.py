"""Checking a log end to end, and the one way past real corruption: an explicit repair.

A writer refuses a damaged log and touches nothing (``CorruptLogError``); only a person running
``objsearch log repair`` changes one, and the repair removes nothing it does not keep: the bytes it
takes out of ``events.log`` go to a quarantine file beside it, named in its report. What it keeps
is planned by :mod:`.repair_plan`.
"""

from __future__ import annotations

import collections
import os
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, TypeVar

from . import _fs
from .errors import CorruptLogError, LogLockedError
from .log_files import (
    DURABLE_FILE,
    LOCK_FILE,
    LOG_FILE,
    META_FILE,
    QUARANTINE_PREFIX,
    DurableRecord,
    LogMeta,
    LogPosition,
    read_durable_record,
    read_meta,
    write_durable,
)
from .log_links import line_info, meta_mismatch
from .log_seal_check import _check_sealed
from .log_torn_tail import quarantine
from .repair_output import Plan, RepairAction
from .repair_plan import plan_repair
from .scan import QUARANTINED_TYPE, _Scan
from .schemas import SchemaRegistry
from .seal import Sealer, check_seals
from .store import Store


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
    kept_events: int  # real events in the repaired log (markers not counted)
    kept_last_seq: int  # its last seq (markers included: the next writer continues after it)
    removed_bytes: int  # bytes moved out of events.log (kept in ``quarantine``)
    removed_lines: int  # complete lines among the removed bytes
    problem: str | None  # the first problem found, as CorruptLogError described it
    quarantine: Path | None  # where the removed (or replaced) bytes are kept
    missing_seqs: tuple[int, int] | None  # acknowledged seqs (first, last) the file had lost
    actions: tuple[RepairAction, ...] = ()


T = TypeVar("T")


class Progress(Protocol):
    """Wraps what a pass reads (records, lines) as it is consumed: the CLI's progress line."""

    def __call__(self, items: Iterable[T], /) -> Iterable[T]: ...


def _unwatched(items: Iterable[T], /) -> Iterable[T]:
    return items


def verify_log(
    directory: Path | str,
    *,
    store: Store,
    progress: Progress = _unwatched,
) -> Verification:
    """Read every record and check it, and the seals of ``durable.json``; raise
    :class:`CorruptLogError` at the first problem. ``progress`` wraps the records as they are
    checked (the CLI's progress line)."""
    directory = Path(directory)
    meta = read_meta(directory)
    record = read_durable_record(directory)
    durable = None if record is None else record.position
    registry = store.registry
    scan = _Scan(directory / LOG_FILE, meta, registry=registry, durable=durable, payloads=False)
    # every record checked; none kept
    collections.deque(progress(scan), maxlen=0)
    events = scan.at.line  # the records read (a scan from the start counts from 0)
    if record is not None and record.seals:
        _check_sealed(directory, meta, registry, record)
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


def repair_log(
    directory: Path | str,
    *,
    wall_clock: Callable[[], int] = time.time_ns,
    store: Store,
    progress: Progress = _unwatched,
) -> Repair:
    """Make ``directory`` a clean log again, removing only what is damaged and keeping every
    byte it takes out.

    Under the writer's lock: a log whose every line ends in CR LF is converted back first (the
    original kept as ``events.log.crlf``). Each record is then found by its witnesses, not by
    where it stands (:mod:`~objsearch.events.repair_plan`): the next record is the line whose
    checksum was chained from the last one kept, so blank, duplicated, inserted or swapped lines
    cost no record; damage is judged in place (a flipped bit corrected, checksum digits
    rewritten, a record damaged otherwise replaced by a ``record_quarantined`` event that
    carries its chain on); after lines lost or damaged beyond that, the next intact record of
    this log resumes it. What no witness places is moved out, and ``record_quarantined`` events
    take every seq a removed line may have held and any acknowledged seqs the file had lost, so
    no later event reuses a removed record's seq or id. The bytes taken out are kept in
    ``events.log.repair-<offset>``; seals and the high-water mark are rewritten (snapshot
    attestations dropped: the log changed). Raises :class:`CorruptLogError`, changing nothing,
    for a ``meta.json`` the records prove edited (:func:`~.log_links.meta_mismatch`) and where a
    repair would be a guess; :class:`LogLockedError` if a writer has the log open. ``progress``
    wraps the records checked, then the steps of the repair.
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
            registry = store.registry
            return _repair_locked(directory, meta, wall_clock, registry, progress)
        finally:
            os.close(lock_fd)
    finally:
        os.close(fd)


def _repair_locked(
    directory: Path,
    meta: LogMeta,
    wall_clock: Callable[[], int],
    registry: SchemaRegistry,
    progress: Progress,
) -> Repair:
    path = directory / LOG_FILE
    data = path.read_bytes()
    damaged_mark: str | None = None
    try:
        record = read_durable_record(directory)
    except CorruptLogError as exc:
        damaged_mark, record = str(exc), None
    durable = None if record is None else record.position
    problem, events, last_seq = _first_problem(directory, meta, record, registry, progress)
    problem = problem or damaged_mark
    if problem is None:
        return Repair(directory, False, events, last_seq, 0, 0, None, None, None)
    crlf = _is_crlf(data)
    original = data
    if crlf:
        data = data.replace(b"\r\n", b"\n")
    wrong_meta = meta_mismatch(lambda n: data[:n], meta)
    if wrong_meta is not None:
        raise CorruptLogError(
            f"cannot repair {path}: {wrong_meta} (nothing was changed)",
            path=str(directory / META_FILE),
            line=1,
            offset=0,
        )

    def name(offset: int) -> str:
        return _quarantine_name(directory, offset)

    plan = plan_repair(data, meta, durable, registry, wall_clock, name, progress)
    _refuse_what_repair_cannot_judge(directory, meta, data, plan, record)
    if damaged_mark is not None:
        quarantine(directory, "durable-damaged", (directory / DURABLE_FILE).read_bytes())
    if crlf:
        kept_original = quarantine(directory, "crlf", original)
        if plan.clean:
            _fs.write_atomic(path, data)
            _write_mark(directory, meta, plan)
            return Repair(
                directory, True, plan.events, plan.at.seq, 0, 0, problem, kept_original, None
            )
        plan.actions.insert(
            0,
            RepairAction(
                "line-ending-restored",
                1,
                plan.at.seq,
                1,
                0,
                f"every line ended in CR LF: converted back (the file as it was is kept in "
                f"{kept_original.name}); the offsets below are of the converted file",
            ),
        )
    kept: Path | None = None
    if plan.removed:
        kept = directory / plan.quarantine_name
        _fs.write_new(kept, bytes(plan.removed))
    new = plan.output()
    if new != original:
        _fs.write_atomic(path, new)
    if plan.at.seq:
        _write_mark(directory, meta, plan)
    elif record is not None:
        (directory / DURABLE_FILE).unlink()
        _fs.fsync_dir(directory)
    return Repair(
        directory=directory,
        changed=True,
        kept_events=plan.events,
        kept_last_seq=plan.at.seq,
        removed_bytes=len(plan.removed),
        removed_lines=plan.removed.count(b"\n"),
        problem=problem,
        quarantine=kept,
        missing_seqs=plan.missing,
        actions=tuple(plan.actions),
    )


def _refuse_what_repair_cannot_judge(
    directory: Path, meta: LogMeta, data: bytes, plan: Plan, record: DurableRecord | None
) -> None:
    """Raise :class:`CorruptLogError` (nothing changed) where a repair would be a guess."""
    path = directory / LOG_FILE
    if (
        plan.kept_records == 0
        and not plan.actions_before_cut()
        and any(line_info(line).seq is not None for line in data.split(b"\n")[:-1])
    ):
        raise CorruptLogError(
            f"cannot repair {path}: not one record can be proven to belong to the log "
            f"meta.json describes (stream {meta.stream!r}, run id {meta.run_id}, format "
            f"{meta.format!r}): meta.json was probably edited or replaced, or events.log is "
            "another log's, and a repair would move every record out; restore meta.json or "
            "compare with a copy (nothing was changed)",
            path=str(directory / META_FILE),
            line=1,
            offset=0,
        )
    durable = None if record is None else record.position
    if (
        durable is not None
        and plan.mark_chain is not None
        and plan.mark_chain != durable.checksum
        and record is not None
        and record.seals
        and check_seals(path, record.seals, meta.genesis) is not None
    ):
        raise CorruptLogError(
            f"cannot repair {path}: every record verifies, but the chain does not reach the "
            f"checksum its writer closed it with at seq {durable.seq}, and the bytes do not "
            "match their seals: records before the high-water mark were edited and their "
            "checksums recomputed. Which ones cannot be told from the log; compare it with a "
            "copy (nothing was changed)",
            path=str(path),
            line=durable.line,
            offset=durable.offset,
        )


def _first_problem(
    directory: Path,
    meta: LogMeta,
    record: DurableRecord | None,
    registry: SchemaRegistry,
    progress: Progress,
) -> tuple[str | None, int, int]:
    """(the first problem, or None; the events before it, markers not counted; their last
    seq)."""
    durable = None if record is None else record.position
    scan = _Scan(directory / LOG_FILE, meta, registry=registry, durable=durable, payloads=False)
    events = 0
    try:
        for event in progress(scan):
            events += event.type != QUARANTINED_TYPE
        if record is not None and record.seals:
            _check_sealed(directory, meta, registry, record)
    except CorruptLogError as exc:
        return str(exc), events, scan.last_seq
    if scan.torn_tail is not None:
        problem = f"unterminated fragment of {scan.torn_tail.length} byte(s) at the end"
        return problem, events, scan.last_seq
    return None, events, scan.last_seq


def _write_mark(directory: Path, meta: LogMeta, plan: Plan) -> None:
    """The high-water mark at the repaired file's end, sealed from the lines just written (no
    second read of the file)."""
    sealer = Sealer(crc=meta.genesis)
    for line in plan.lines:
        sealer.add(line)
    at = plan.at
    mark = LogPosition(at.seq, at.offset, at.checksum, at.line, at.time_ns)
    write_durable(directory, mark, sealer.seals())


def _quarantine_name(directory: Path, offset: int) -> str:
    name = f"{QUARANTINE_PREFIX}repair-{offset}"
    n = 0
    while (directory / name).exists():
        n += 1
        name = f"{QUARANTINE_PREFIX}repair-{offset}.{n}"
    return name


def _is_crlf(data: bytes) -> bool:
    return data.count(b"\n") > 0 and data.count(b"\r\n") == data.count(b"\n")
