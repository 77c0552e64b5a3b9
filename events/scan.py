"""One checked pass over ``events.log``: every record verified (checksum chain, envelope, seq,
stream, known type and version, time order, the durable mark) and the good events yielded."""

from __future__ import annotations

import json
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Final, NoReturn

import msgspec

from .diagnose import Witness, diagnose
from .envelope import Event, canonical_ids, decode_event, frame_event
from .errors import (
    CorruptLogError,
    InvalidEventError,
)
from .log_files import DURABLE_FILE, Durable, LogMeta, LogPosition, TornTail
from .log_links import meta_mismatch
from .record import RECORD_SEPARATOR, RecordError, decode_record
from .schemas import SchemaRegistry
from .seal import Sealer


@dataclass(slots=True)
class _Cursor:
    """Where a scan stands: after the record ending at ``offset`` (line ``line``, seq ``seq``)."""

    offset: int = 0
    line: int = 0
    seq: int = 0
    checksum: int = 0
    time_ns: int = 0

    def move_to(self, offset: int, line: int, seq: int, checksum: int, time_ns: int) -> None:
        self.offset, self.line, self.seq, self.checksum, self.time_ns = (
            offset,
            line,
            seq,
            checksum,
            time_ns,
        )


class _Scan:
    """One pass over ``events.log`` that checks every record and yields the good events in order.

    Only an unterminated fragment after the last newline is a torn tail (``torn_tail``); any
    complete line that is not a valid record, a broken checksum chain, a seq gap, a record of
    another stream, an event type or version this code does not know, time running backwards,
    or a log that ends before its durable high-water mark is a :class:`CorruptLogError`.
    """

    def __init__(
        self,
        path: Path,
        meta: LogMeta,
        *,
        registry: SchemaRegistry,
        durable: Durable | None = None,
        stop_after: int | None = None,
        start: _Cursor | LogPosition | None = None,
        ids: dict[str, int] | None = None,
        sealer: Sealer | None = None,
        payloads: bool = True,
    ) -> None:
        self.path = path
        #: False: the events yielded keep their payload as JSON text (a scan that only checks)
        self.payloads = payloads
        self.meta = meta
        self.registry = registry
        self.durable = durable
        self.stop_after = stop_after
        self.torn_tail: TornTail | None = None
        if isinstance(start, LogPosition):
            start = _Cursor(start.offset, start.line, start.seq, start.checksum, start.time_ns)
        self.at = start if start is not None else _Cursor(checksum=meta.genesis)
        #: when given, filled with event id → byte offset of its record (for idempotent appends)
        self.ids = ids
        #: when given, fed every verified record's bytes (a writer's seals)
        self.sealer = sealer

    @property
    def end_offset(self) -> int:
        return self.at.offset

    @property
    def last_seq(self) -> int:
        return self.at.seq

    def __iter__(self) -> Iterator[Event]:
        try:
            f = self.path.open("rb")
        except FileNotFoundError:
            f = None  # meta.json written, crash before events.log existed: an empty log
        if f is not None:
            with f:
                if self.at.offset:
                    f.seek(self.at.offset)
                yield from self._lines(f)
        if self.stop_after is None or self.at.seq < self.stop_after:
            self._check_durable()

    def _lines(self, f: IO[bytes]) -> Iterator[Event]:
        at = self.at
        # The cursor lives in locals while the loop runs (its attributes cost a fifth of a scan
        # that only verifies) and is written back to ``self.at`` before anything reads it: the
        # slow path, and on every way out (the end, a return, an error, the caller stopping).
        offset, line_no, seq, checksum, time_ns = (
            at.offset,
            at.line,
            at.seq,
            at.checksum,
            at.time_ns,
        )
        meta = self.meta
        registry = self.registry
        stream = meta.stream
        chained = meta.chained
        known = registry.known
        mark = self.durable
        mark_seq = mark.seq if mark is not None else -1
        ids = self.ids
        sealer = self.sealer
        stop_after = self.stop_after
        crc32 = zlib.crc32
        decode = decode_event if self.payloads else frame_event
        # A scan that only verifies decodes with ``frame_event``, which leaves the ids' spelling
        # to the scan: checked a batch at a time (``pending``: the ids since ``batch``, the cursor
        # before them), and before anything else is reported, so the first bad record is the one
        # named.
        framed = not self.payloads
        pending: list[str] = []
        batch = _Cursor(offset, line_no, seq, checksum, time_ns)
        try:
            for line in f:
                start = offset
                if line[-1:] != b"\n":
                    # The only shape an interrupted append can leave: bytes after the last newline.
                    self._check_ids(pending, batch)
                    self.torn_tail = TornTail(
                        path=self.path, offset=start, length=len(line), line=line_no + 1
                    )
                    return
                # The fast path: a record whose checksum, envelope, place and type all hold, read
                # with one decode (check_record is the same checks, spelled out, with the reasons).
                body, sep, crc = line.rpartition(RECORD_SEPARATOR)
                value = crc32(body, checksum if chained else 0)
                event: Event | None = None
                if sep and crc == b"%08x\n" % value:
                    try:
                        event = decode(body)
                    except msgspec.MsgspecError:
                        event = None
                if (
                    event is None
                    or event.seq != seq + 1
                    or event.stream != stream
                    or (event.type, event.version) not in known
                    or event.time_ns < time_ns
                    or event.type == QUARANTINED_TYPE
                    or (framed and bytes(event.payload)[:1] != b"{")  # type: ignore[arg-type]
                ):
                    here = _Cursor(offset, line_no, seq, checksum, time_ns)
                    event, value = self._check_slowly(line, f, pending, batch, here)
                    batch = here
                offset = start + len(line)
                line_no += 1
                seq = event.seq
                checksum = value
                time_ns = event.time_ns
                if seq == mark_seq:
                    assert mark is not None
                    if offset != mark.offset or checksum != mark.checksum:
                        self._corrupt(
                            line_no,
                            start,
                            f"the record at seq {mark.seq} is not the one its writer closed the "
                            f"log with ({DURABLE_FILE}: ends at byte {mark.offset}, checksum "
                            f"{mark.checksum:08x})",
                        )
                if ids is not None:
                    ids[event.event_id] = start
                if sealer is not None:
                    sealer.add(line)
                if framed:
                    pending.append(event.event_id)
                    if len(pending) == _ID_BATCH:
                        self._check_ids(pending, batch)
                        batch = _Cursor(offset, line_no, seq, checksum, time_ns)
                yield event
                if stop_after is not None and seq >= stop_after:
                    self._check_ids(pending, batch)
                    return
            self._check_ids(pending, batch)
        finally:
            at.move_to(offset, line_no, seq, checksum, time_ns)

    def _check_slowly(
        self, line: bytes, f: IO[bytes], pending: list[str], batch: _Cursor, here: _Cursor
    ) -> tuple[Event, int]:
        """The slow path of :meth:`_lines`, for a record its fast path did not take: ``line``
        (with its newline) checked after ``here`` by :func:`check_record`, which says why a
        record fails. The ids read since ``batch`` are checked first, so an earlier record's
        bad id is reported before this record's fault; the cursor moves to ``here`` before
        anything reads it."""
        self._check_ids(pending, batch)
        at = self.at
        at.move_to(here.offset, here.line, here.seq, here.checksum, here.time_ns)
        try:
            return check_record(line[:-1], at, self.meta, self.registry)
        except BadRecord as exc:
            reason = exc.reason
            if exc.record_error is not None:
                reason = self._explain(line[:-1], exc.record_error, f)
            if here.offset == 0:
                reason = self._meta_reason() or reason
            self._corrupt(here.line + 1, here.offset, reason)

    def _check_ids(self, ids: list[str], batch: _Cursor) -> None:
        """Check the ids of the records read since ``batch`` (and forget them); if one is not
        canonical, read those records again one by one from ``batch`` and report the first bad
        one as the slow path words it."""
        if not ids:
            return
        good = canonical_ids(ids)
        count = len(ids)
        ids.clear()
        if good:
            return
        at = _Cursor(batch.offset, batch.line, batch.seq, batch.checksum, batch.time_ns)
        with self.path.open("rb") as f:
            f.seek(at.offset)
            for _ in range(count):
                line = f.readline()
                try:
                    event, value = check_record(line[:-1], at, self.meta, self.registry)
                except BadRecord as exc:
                    reason = exc.reason
                    if exc.record_error is not None:
                        self.at.move_to(at.offset, at.line, at.seq, at.checksum, at.time_ns)
                        reason = self._explain(line[:-1], exc.record_error, f)
                    self._corrupt(at.line + 1, at.offset, reason)
                at.move_to(at.offset + len(line), at.line + 1, event.seq, value, event.time_ns)
        raise AssertionError(f"{self.path}: canonical_ids refused ids that check_record accepts")

    def _explain(self, line: bytes, exc: RecordError, f: IO[bytes]) -> str:
        reason = exc.reason
        if not exc.intact and not line.endswith(b"\r"):
            after = f.readline()  # the witness: the next record chains from this one's checksum
            mark = self.durable
            at = self.at
            witness = Witness(
                after[:-1] if after.endswith(b"\n") else None,
                mark.checksum
                if mark is not None
                and mark.seq == at.seq + 1
                and mark.offset == at.offset + len(line) + 1
                else None,
            )
            found = diagnose(
                line,
                at.checksum,
                seq=at.seq + 1,
                stream=self.meta.stream,
                id_key=self.meta.id_key(),
                chained=self.meta.chained,
                witness=witness,
            )
            if found.kind == "extra":
                return f"{found.reason} ({reason})"
            if found.kind == "lost":
                return (
                    f"this log's record of seq {found.found_seq} stands where seq {at.seq + 1} "
                    f"belongs: the records before it are missing or out of order ({reason})"
                )
            if found.kind != "unproven":
                return f"record at seq {at.seq + 1} is damaged: {found.reason} ({reason})"
        if line.endswith(b"\r"):
            return (
                f"{reason}; the line ends in CR LF: its line endings were converted (git "
                "core.autocrlf, an editor), `objsearch log repair` can convert them back"
            )
        if exc.intact:
            return reason
        try:
            Event._adopt(json.loads(line.rpartition(b"\t")[0]))
        except (ValueError, InvalidEventError):
            return reason
        return (
            f"{reason}: the record reads as a whole, valid event, so it was most likely not "
            "damaged but spliced, reordered or copied from another log (its checksum does not "
            "follow its predecessor)"
        )

    def _meta_reason(self) -> str | None:
        """Why the first record fails: ``meta.json`` is not the one the records were written
        under (:func:`~.log_links.meta_mismatch`), if its witnesses prove it."""

        def prefix(n: int) -> bytes:
            with self.path.open("rb") as f:
                return f.read(n)

        return meta_mismatch(prefix, self.meta)

    def _check_durable(self) -> None:
        mark = self.durable
        if mark is None:
            return
        at = self.at
        if at.offset < mark.offset or at.seq < mark.seq:
            lost = "" if self.torn_tail is None else " (the rest is an unterminated fragment)"
            self._corrupt(
                at.line + 1,
                at.offset,
                f"the log ends at seq {at.seq} (byte {at.offset}){lost}, but its writer closed "
                f"it at seq {mark.seq} (byte {mark.offset}, {DURABLE_FILE}): acknowledged "
                "records are missing",
            )

    def _corrupt(self, line: int, offset: int, reason: str) -> NoReturn:
        raise CorruptLogError(
            f"corrupt event log {self.path}: line {line} (byte offset {offset}): {reason}; "
            "the log was not changed (`objsearch log repair` keeps what it removes)",
            path=str(self.path),
            line=line,
            offset=offset,
        )


#: How many ids a verifying scan checks at once (:meth:`_Scan._check_ids`).
_ID_BATCH: Final = 1024

#: The type ``objsearch log repair`` writes in the place of a record it moved out; the one type
#: the store reads a field of (``chain``: where the next record's checksum chain continues from).
QUARANTINED_TYPE: Final = "record_quarantined"


class BadRecord(Exception):
    """A complete line that is not the next valid record (``record_error``: its own framing,
    checksum or envelope is wrong, rather than where it stands)."""

    def __init__(self, reason: str, record_error: RecordError | None = None) -> None:
        super().__init__(reason)
        self.reason = reason
        self.record_error = record_error


def check_record(
    line: bytes, at: _Cursor | LogPosition, meta: LogMeta, registry: SchemaRegistry
) -> tuple[Event, int]:
    """The event of ``line`` (no newline) if it is the valid record after ``at``, and the chain
    value the next record continues from; :class:`BadRecord` saying why not."""
    try:
        event, checksum = decode_record(line, at.checksum if meta.chained else 0)
    except RecordError as exc:
        raise BadRecord(exc.reason, exc) from None
    if event.stream != meta.stream:
        raise BadRecord(f"record of stream {event.stream!r} in the log of stream {meta.stream!r}")
    if event.seq != at.seq + 1:
        raise BadRecord(f"expected seq {at.seq + 1}, found seq {event.seq}")
    if not registry.knows(event.type, event.version):
        raise BadRecord(
            f"event type {event.type!r} version {event.version} is not one this code "
            "knows (written by newer code, or damaged)"
        )
    if event.time_ns < at.time_ns:
        raise BadRecord(f"time runs backwards: time_ns {event.time_ns} after {at.time_ns}")
    if event.type == QUARANTINED_TYPE:
        chain = event.payload.get("chain")
        if chain is not None:
            if not (isinstance(chain, str) and len(chain) == 8 and chain == chain.lower()):
                raise BadRecord(f"{QUARANTINED_TYPE}: chain {chain!r} is not 8 hex digits")
            try:
                checksum = int(chain, 16)
            except ValueError:
                raise BadRecord(
                    f"{QUARANTINED_TYPE}: chain {chain!r} is not 8 hex digits"
                ) from None
    return event, checksum
