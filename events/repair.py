"""Checking a log end to end, and the one way past real corruption: an explicit repair.

A writer refuses a damaged log and touches nothing (``CorruptLogError``); only a person running
``objsearch log repair`` changes one, and the repair removes nothing it does not keep: the bytes it
takes out of ``events.log`` go to a quarantine file beside it, named in its report.
"""

from __future__ import annotations

import collections
import json
import os
import time
import uuid
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol, TypeVar

from . import _fs
from .diagnose import Witness, diagnose
from .envelope import EVENT_ID_NAMESPACE, Event, deterministic_event_id
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
from .log_seal_check import _check_sealed
from .log_torn_tail import quarantine
from .record import encode_record
from .scan import QUARANTINED_TYPE, BadRecord, _Cursor, _Scan, check_record
from .schemas import SchemaRegistry
from .seal import Sealer, check_seals
from .store import Store, shipped


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
class RepairAction:
    """One thing :func:`repair_log` did, at one place of the original file."""

    #: "checksum-rewritten", "bit-restored", "quarantined", "extra", "lost", "cut", "missing"
    kind: str
    first_seq: int  # the seq(s) it concerns
    last_seq: int
    line: int  # line (1-based) and byte offset in the file as it was (the end, for "missing")
    offset: int
    reason: str


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
    store: Store | None = None,
    progress: Progress = _unwatched,
) -> Verification:
    """Read every record and check it, and the seals of ``durable.json``; raise
    :class:`CorruptLogError` at the first problem. ``progress`` wraps the records as they are
    checked (the CLI's progress line)."""
    directory = Path(directory)
    meta = read_meta(directory)
    record = read_durable_record(directory)
    durable = None if record is None else record.position
    registry = (store or shipped()).registry
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
    store: Store | None = None,
    progress: Progress = _unwatched,
) -> Repair:
    """Make ``directory`` a clean log again, removing only what is damaged and keeping every
    byte it takes out.

    Under the writer's lock: a log whose every line ends in CR LF is converted back (the
    original kept as ``events.log.crlf``) if that makes it clean. Otherwise each bad record is
    diagnosed by its witness, the next record (:mod:`~objsearch.events.diagnose`): checksum
    digits damaged on an intact record are rewritten; a single flipped bit is corrected; a
    record damaged otherwise is replaced by a ``record_quarantined`` event at its seq that
    carries its checksum on, so every later record stays. From the first record nothing proves
    (spliced, reordered, two damaged in a row, lines lost) everything is moved out, and
    ``record_quarantined`` events take the seqs it held and any acknowledged seqs the file had
    lost, so no later event reuses a removed record's seq or id. The bytes taken out are kept in
    ``events.log.repair-<offset>``; seals and the high-water mark are rewritten (snapshot
    attestations dropped: the log changed). Raises :class:`LogLockedError` if a writer has the
    log open. ``progress`` wraps the records checked, then (a damaged log) the lines judged.
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
            registry = (store or shipped()).registry
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
    if damaged_mark is not None:
        quarantine(directory, "durable-damaged", (directory / DURABLE_FILE).read_bytes())
    if _is_crlf(data):
        converted = data.replace(b"\r\n", b"\n")
        plan = _plan(converted, meta, durable, wall_clock, directory, registry, progress)
        if not plan.actions and plan.end == len(converted):
            original = quarantine(directory, "crlf", data)
            _fs.write_atomic(path, converted)
            _write_mark(directory, meta, plan)
            return Repair(directory, True, plan.events, plan.at.seq, 0, 0, problem, original, None)
    plan = _plan(data, meta, durable, wall_clock, directory, registry, progress)
    _refuse_what_repair_cannot_judge(directory, meta, data, plan, record)
    kept: Path | None = None
    if plan.removed:
        kept = directory / plan.quarantine_name
        _fs.write_new(kept, bytes(plan.removed))
    new = plan.output()
    if new != data:
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
    directory: Path, meta: LogMeta, data: bytes, plan: _Plan, record: DurableRecord | None
) -> None:
    """Raise :class:`CorruptLogError` (nothing changed) where a repair would be a guess."""
    path = directory / LOG_FILE
    if plan.events == 0 and data.count(b"\n") > 0 and not plan.actions_before_cut():
        raise CorruptLogError(
            f"cannot repair {path}: not one record belongs to the log meta.json describes "
            f"(stream {meta.stream!r}, run id {meta.run_id}): meta.json was probably edited or "
            "replaced, and a repair would move every record out; restore meta.json (nothing "
            "was changed)",
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


def _write_mark(directory: Path, meta: LogMeta, plan: _Plan) -> None:
    """The high-water mark at the repaired file's end, sealed from the lines just written (no
    second read of the file)."""
    sealer = Sealer(crc=meta.genesis)
    for line in plan.lines:
        sealer.add(line)
    at = plan.at
    mark = LogPosition(at.seq, at.offset, at.checksum, at.line, at.time_ns)
    write_durable(directory, mark, sealer.seals())


@dataclass
class _Plan:
    """The repaired file, built line by line from the damaged one."""

    meta: LogMeta
    wall_clock: Callable[[], int]
    quarantine_name: str = ""
    at: _Cursor = field(default_factory=_Cursor)
    lines: list[bytes] = field(default_factory=list)  # the new file's lines, newlines included
    removed: bytearray = field(default_factory=bytearray)
    actions: list[RepairAction] = field(default_factory=list)
    events: int = 0
    end: int = 0  # bytes of the original file read as kept records
    missing: tuple[int, int] | None = None
    mark_seq: int = 0  # the durable mark's seq, and the chain value the repair reached there
    mark_chain: int | None = None

    def actions_before_cut(self) -> bool:
        return any(a.kind != "cut" and a.kind != "missing" for a in self.actions)

    def keep(self, line: bytes, event: Event, chain: int) -> None:
        self.lines.append(line + b"\n")
        at = self.at
        at.offset += len(line) + 1
        at.line += 1
        at.seq = event.seq
        at.checksum = chain
        at.time_ns = event.time_ns
        if event.seq == self.mark_seq and not self.actions:
            self.mark_chain = chain  # every record up to the mark verified as it stands
        if event.type != QUARANTINED_TYPE:
            self.events += 1

    def marker(
        self, *, reason: str, offset: int, length: int, chain: int | None, kept: bool
    ) -> None:
        """A ``record_quarantined`` event at the next seq."""
        at = self.at
        seq = at.seq + 1
        event = Event(
            event_id=str(uuid.uuid5(EVENT_ID_NAMESPACE, f"{self.meta.id_key()}/{seq}/quarantined")),
            stream=self.meta.stream,
            seq=seq,
            time_ns=at.time_ns,
            recorded_at_ns=self.wall_clock(),
            type=QUARANTINED_TYPE,
            version=1,
            task_id=None,
            payload={
                "reason": reason,
                "quarantine": self.quarantine_name if kept else None,
                "offset": offset,
                "length": length,
                "chain": None if chain is None else f"{chain:08x}",
            },
        )
        line = encode_record(event, at.checksum if self.meta.chained else 0)[:-1]
        own = int(line[-8:], 16)
        self.keep(line, event, own if chain is None else chain)

    def output(self) -> bytes:
        return b"".join(self.lines)


def _plan(
    data: bytes,
    meta: LogMeta,
    durable: LogPosition | None,
    wall_clock: Callable[[], int],
    directory: Path,
    registry: SchemaRegistry,
    progress: Progress,
) -> _Plan:
    plan = _Plan(meta, wall_clock, mark_seq=0 if durable is None else durable.seq)
    plan.at.checksum = meta.genesis
    lines = data.split(b"\n")
    lines.pop()  # the unterminated fragment after the last newline (b"" if none): part of the tail
    offsets = [0]
    for line in lines:
        offsets.append(offsets[-1] + len(line) + 1)
    first_change: int | None = None
    stop = len(lines)  # the first line from which nothing is proven (the tail), or past the last
    for i, line in enumerate(progress(lines)):
        at = plan.at
        try:
            event, chain = check_record(line, at, meta, registry)
        except BadRecord as bad:
            found = None
            if bad.record_error is not None and not bad.record_error.intact:
                mark = None
                if (
                    durable is not None
                    and durable.seq == at.seq + 1
                    and durable.offset == offsets[i + 1]
                ):
                    mark = durable.checksum
                found = diagnose(
                    line,
                    at.checksum,
                    seq=at.seq + 1,
                    stream=meta.stream,
                    id_key=meta.id_key(),
                    chained=meta.chained,
                    witness=Witness(lines[i + 1] if i + 1 < len(lines) else None, mark),
                )
            if found is None or found.kind == "unproven":
                stop = i
                break
            restored = None
            if found.original is not None:
                try:
                    restored = check_record(found.original, at, meta, registry)
                except BadRecord:
                    stop = i
                    break  # recovered bytes that are still not the next record: prove nothing
            if first_change is None:
                first_change = offsets[i]
                plan.quarantine_name = _quarantine_name(directory, first_change)
            kept_at = len(plan.removed)
            plan.removed += line + b"\n"
            seq = at.seq + 1
            if restored is not None and found.original is not None:
                plan.keep(found.original, *restored)
                kind = "checksum-rewritten" if found.kind == "checksum" else "bit-restored"
            elif found.kind == "lost":
                plan.removed = plan.removed[:kept_at]  # the line stays: only seqs were lost
                last = found.found_seq - 1
                while plan.at.seq < last:
                    plan.marker(
                        reason=f"missing: {found.reason}",
                        offset=0,
                        length=0,
                        chain=found.chain if plan.at.seq + 1 == last else None,
                        kept=False,
                    )
                try:
                    kept_event, chain = check_record(line, plan.at, meta, registry)
                except BadRecord:
                    raise AssertionError("a solved chain that does not verify") from None
                plan.keep(line, kept_event, chain)
                plan.actions.append(
                    RepairAction("lost", seq, last, i + 1, offsets[i], found.reason)
                )
                continue
            elif found.kind == "extra":
                plan.actions.append(
                    RepairAction("extra", seq, seq, i + 1, offsets[i], found.reason)
                )
                continue
            else:
                plan.marker(
                    reason=f"damaged: {found.reason}",
                    offset=kept_at,
                    length=len(line) + 1,
                    chain=found.chain if meta.chained else None,
                    kept=True,
                )
                kind = "quarantined"
            plan.actions.append(RepairAction(kind, seq, seq, i + 1, offsets[i], found.reason))
            continue
        plan.keep(line, event, chain)
    i = stop
    plan.end = offsets[i]
    tail = data[offsets[i] :]
    first_seq = plan.at.seq + 1
    if tail:
        if first_change is None:
            first_change = offsets[i]
            plan.quarantine_name = _quarantine_name(directory, first_change)
        kept_at = len(plan.removed)
        plan.removed += tail
        complete = len(lines) - i
        why = (
            "an unterminated fragment (an interrupted append, never acknowledged)"
            if complete == 0
            else "from here on no record can be proven to belong to this log (spliced, "
            "reordered, copied from another log, two damaged in a row, or lines lost before it)"
        )
        # Every seq a removed line may have held is taken by a marker, so no later event reuses
        # a removed record's seq or id: as many as there were lines, and up to the highest seq
        # a removed line provably held (this log's own id at that seq; a line may have been
        # lost before it).
        last = max(plan.at.seq + complete, _highest_own_seq(lines[i:], meta))
        plan.actions.append(RepairAction("cut", first_seq, last, i + 1, offsets[i], why))
        while plan.at.seq < last:
            plan.marker(
                reason=f"moved out: {why}", offset=kept_at, length=len(tail), chain=None, kept=True
            )
    if durable is not None and durable.seq > plan.at.seq:
        lost_from = plan.at.seq + 1
        plan.missing = (lost_from, durable.seq)
        plan.actions.append(
            RepairAction(
                "missing",
                lost_from,
                durable.seq,
                len(lines) + 1,
                len(data),
                "acknowledged (below the high-water mark) but no longer in the file",
            )
        )
        while plan.at.seq < durable.seq:
            plan.marker(
                reason="missing: acknowledged, but the file had already lost it",
                offset=0,
                length=0,
                chain=None,
                kept=False,
            )
    return plan


def _highest_own_seq(lines: list[bytes], meta: LogMeta) -> int:
    highest = 0
    key = meta.id_key()
    for line in lines:
        try:
            doc = json.loads(line.rpartition(b"\t")[0])
            seq = doc["seq"]
            if (
                type(seq) is int
                and seq > highest
                and doc.get("stream") == meta.stream
                and doc.get("event_id") == deterministic_event_id(key, seq)
            ):
                highest = seq
        except (ValueError, KeyError, TypeError):
            continue
    return highest


def _quarantine_name(directory: Path, offset: int) -> str:
    name = f"{QUARANTINE_PREFIX}repair-{offset}"
    n = 0
    while (directory / name).exists():
        n += 1
        name = f"{QUARANTINE_PREFIX}repair-{offset}.{n}"
    return name


def _is_crlf(data: bytes) -> bool:
    return data.count(b"\n") > 0 and data.count(b"\r\n") == data.count(b"\n")
