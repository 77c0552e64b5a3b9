"""The append-only event log: one stream per directory.

Layout of a log directory::

    meta.json    {"format": "objsearch.events/1", "stream": "<stream>"}, written once, atomically
    events.log   one record per line (see record.py); only ever appended to, or cut at a torn tail
    LOCK         flock'ed by the single writer; holds its pid as a hint

``meta.json`` exists because the records alone can't say which stream an empty log belongs to or
which on-disk format a directory uses; a reader refuses a format it doesn't know instead of
reporting every line as corrupt.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import time
import warnings
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import IO, Any, Final, NoReturn

from . import _fs
from .envelope import Event, deterministic_event_id
from .errors import (
    CorruptLogError,
    DuplicateEventError,
    EventStoreError,
    LogClosedError,
    LogLockedError,
    LogNotFoundError,
    StreamMismatchError,
    TornTailWarning,
    WrongExpectedSeqError,
)
from .record import RecordError, checksum_ok, decode_record, encode_record
from .schemas import SchemaRegistry, default_registry
from .upcast import default_upcaster

LOG_FORMAT: Final = "objsearch.events/1"
LOG_FILE: Final = "events.log"
META_FILE: Final = "meta.json"
LOCK_FILE: Final = "LOCK"

_log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class TornTail:
    """Bytes after the last good record that belong to no acknowledged append."""

    path: Path
    offset: int  # where the last good record ends: the file is cut (or read) up to here
    length: int  # bytes from ``offset`` to the end of the file
    line: int  # line number (1-based) where the damage starts
    lines: int  # lines in the tail, counting an unterminated last one
    complete: bool  # whether the tail ends with a newline
    reason: str


class _Scan:
    """One pass over ``events.log`` that checks framing, checksums, stream and seq continuity.

    Yields good events in order. A damaged line is only a torn tail if nothing but damage
    follows it; a checksum-valid record after it means the damage is in the middle, and that is
    a :class:`CorruptLogError`. After the iteration ends, ``torn_tail``, ``end_offset`` and
    ``last_seq`` describe what was found.
    """

    def __init__(
        self,
        path: Path,
        stream: str,
        *,
        stop_after: int | None = None,
        start: tuple[int, int, int] = (0, 0, 0),
        ids: dict[str, int] | None = None,
    ) -> None:
        self.path = path
        self.stream = stream
        self.stop_after = stop_after
        self.torn_tail: TornTail | None = None
        # (byte offset, line number, seq) of the end of the last good record: where a resumed
        # scan (a tailing reader) starts, having checked everything before it.
        self.end_offset, self.end_line, self.last_seq = start
        #: when given, filled with event id → byte offset of its record (for idempotent appends)
        self.ids = ids

    def __iter__(self) -> Iterator[Event]:
        try:
            f = self.path.open("rb")
        except FileNotFoundError:
            return  # meta.json written, crash before events.log existed: an empty log
        with f:
            if self.end_offset:
                f.seek(self.end_offset)
            yield from self._lines(f)

    def _lines(self, f: IO[bytes]) -> Iterator[Event]:
        offset = self.end_offset
        line_no = self.end_line
        damage: tuple[int, int, str] | None = None  # (line, offset, reason) of the first bad line
        complete = True
        for line in f:
            line_no += 1
            start = offset
            offset += len(line)
            complete = line.endswith(b"\n")
            if damage is not None:
                if complete and checksum_ok(line[:-1]):
                    self._corrupt(
                        damage[0],
                        damage[1],
                        f"{damage[2]}; a valid record follows at line {line_no}, so this is "
                        "not a torn tail",
                    )
                continue
            if not complete:
                damage = (line_no, start, "last line has no newline (interrupted append)")
                continue
            try:
                event = decode_record(line[:-1])
            except RecordError as exc:
                if exc.intact:
                    self._corrupt(line_no, start, exc.reason)
                damage = (line_no, start, exc.reason)
                continue
            if event.stream != self.stream:
                self._corrupt(
                    line_no,
                    start,
                    f"record of stream {event.stream!r} in the log of stream {self.stream!r}",
                )
            if event.seq != self.last_seq + 1:
                self._corrupt(
                    line_no, start, f"expected seq {self.last_seq + 1}, found seq {event.seq}"
                )
            self.last_seq = event.seq
            self.end_offset = offset
            self.end_line = line_no
            if self.ids is not None:
                self.ids[event.event_id] = start
            yield event
            if self.stop_after is not None and event.seq >= self.stop_after:
                return
        if damage is not None:
            self.torn_tail = TornTail(
                path=self.path,
                offset=damage[1],
                length=offset - damage[1],
                line=damage[0],
                lines=line_no - damage[0] + 1,
                complete=complete,
                reason=damage[2],
            )

    def _corrupt(self, line: int, offset: int, reason: str) -> NoReturn:
        raise CorruptLogError(
            f"corrupt event log {self.path}: line {line} (byte offset {offset}): {reason}; "
            "the log was not changed and needs manual repair",
            path=str(self.path),
            line=line,
            offset=offset,
        )


class EventLog:
    """The single writer of one stream's log. Use :meth:`open`; close it (or use ``with``).

    Every append is validated before a byte is written, and is on disk (written and fsync'ed)
    before it returns, except inside :meth:`batch`, which fsyncs once at its end. Not
    thread-safe: the lock makes this the stream's only writer, so give it one thread too.
    """

    def __init__(
        self,
        *,
        directory: Path,
        stream: str,
        fd: int,
        lock_fd: int,
        size: int,
        last_seq: int,
        torn_tail: TornTail | None,
        registry: SchemaRegistry,
        wall_clock: Callable[[], int],
        ids: dict[str, int],
    ) -> None:
        # Private: only open() knows how to reach a consistent state (lock, meta, recovery).
        self._directory = directory
        self._stream = stream
        self._fd = fd
        self._lock_fd = lock_fd
        self._size = size
        self._last_seq = last_seq
        self._torn_tail = torn_tail
        self._registry = registry
        self._wall_clock = wall_clock
        self._ids = ids  # event id → byte offset of its record: what makes appends idempotent
        self._batch_depth = 0
        self._unsynced = False
        self._closed = False
        self._broken: str | None = None

    @classmethod
    def open(
        cls,
        directory: Path | str,
        stream: str,
        *,
        create: bool = True,
        registry: SchemaRegistry | None = None,
        wall_clock: Callable[[], int] = time.time_ns,
    ) -> EventLog:
        """Open ``directory`` for appending to ``stream``, creating it if allowed.

        Takes the directory's lock (:class:`LogLockedError` if another writer has it), checks
        the format and stream (:class:`StreamMismatchError`), verifies every record
        (:class:`CorruptLogError`) and cuts a torn tail with a :class:`TornTailWarning`.
        ``wall_clock`` stamps ``recorded_at_ns``; pass a fixed one for byte-identical logs.
        """
        directory = Path(directory)
        if not (isinstance(stream, str) and stream):
            raise ValueError(f"stream must be a non-empty string, got {stream!r}")
        if not directory.is_dir():
            if not create:
                raise LogNotFoundError(
                    f"no event log at {directory}: the directory does not exist (create=False)"
                )
            _fs.make_dirs(directory)
        elif not create:
            _read_meta(directory)  # raises LogNotFoundError before a LOCK file is left behind

        lock_path = directory / LOCK_FILE
        lock_fd = _fs.try_lock(lock_path)
        if lock_fd is None:
            raise LogLockedError(
                f"event log {directory} is already open for writing (lock {lock_path} is held"
                f"{_fs.lock_holder_hint(lock_path)}); a stream has exactly one writer"
            )
        try:
            return cls._open_locked(directory, stream, lock_fd, create, registry, wall_clock)
        except BaseException:
            os.close(lock_fd)
            raise

    @classmethod
    def _open_locked(
        cls,
        directory: Path,
        stream: str,
        lock_fd: int,
        create: bool,
        registry: SchemaRegistry | None,
        wall_clock: Callable[[], int],
    ) -> EventLog:
        log_path = directory / LOG_FILE
        if (directory / META_FILE).exists() or log_path.exists() or not create:
            found = _read_meta(directory)
            if found != stream:
                raise StreamMismatchError(
                    f"event log {directory} belongs to stream {found!r}, not {stream!r}"
                )
        else:
            meta = {"format": LOG_FORMAT, "stream": stream}
            data = json.dumps(meta, sort_keys=True, ensure_ascii=False).encode() + b"\n"
            _fs.write_atomic(directory / META_FILE, data)

        created = not log_path.exists()
        fd = os.open(log_path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_CLOEXEC, 0o644)
        try:
            if created:
                _fs.fsync_dir(directory)
            scan = _Scan(log_path, stream, ids={})
            for _ in scan:
                pass
            if scan.torn_tail is not None:
                _cut_torn_tail(fd, scan.torn_tail)
        except BaseException:
            os.close(fd)
            raise
        return cls(
            directory=directory,
            stream=stream,
            fd=fd,
            lock_fd=lock_fd,
            size=scan.end_offset,
            last_seq=scan.last_seq,
            torn_tail=scan.torn_tail,
            registry=registry if registry is not None else default_registry(),
            wall_clock=wall_clock,
            ids=scan.ids if scan.ids is not None else {},
        )

    @property
    def directory(self) -> Path:
        return self._directory

    @property
    def stream(self) -> str:
        return self._stream

    @property
    def last_seq(self) -> int:
        """Seq of the last appended record (0 for an empty log)."""
        return self._last_seq

    @property
    def torn_tail(self) -> TornTail | None:
        """What :meth:`open` cut from the end of the file, if anything."""
        return self._torn_tail

    @property
    def closed(self) -> bool:
        return self._closed

    def append(
        self,
        type: str,
        payload: Mapping[str, Any],
        *,
        time_ns: int,
        task_id: str | None = None,
        version: int | None = None,
        event_id: str | None = None,
        expected_last_seq: int | None = None,
    ) -> Event:
        """Validate, write and (outside a batch) fsync one event; return it as stored.

        ``version`` defaults to the type's latest schema version, ``event_id`` to
        :func:`deterministic_event_id`. Raises :class:`InvalidEventError` with the file unchanged.

        Idempotent by event id: if the stream already holds ``event_id`` with the same type,
        version, task, time and payload, nothing is written and the stored event is returned
        (re-running an import never duplicates); the same id with other content raises
        :class:`DuplicateEventError`. With ``expected_last_seq``, the append is refused with
        :class:`WrongExpectedSeqError` unless the log ends at that seq (optimistic concurrency,
        like an expected version); the duplicate check comes first, so a retry still succeeds.
        """
        self._check_usable()
        if version is None:
            version = self._registry.latest_version(type)
        seq = self._last_seq + 1
        if event_id is not None and event_id in self._ids:
            return self._existing(event_id, type, version, payload, time_ns, task_id)
        if expected_last_seq is not None and expected_last_seq != self._last_seq:
            raise WrongExpectedSeqError(
                f"event log {self._directory} ends at seq {self._last_seq}, "
                f"not at the expected seq {expected_last_seq}; nothing was written"
            )
        if event_id is None:
            event_id = deterministic_event_id(self._stream, seq)
            if event_id in self._ids:
                raise DuplicateEventError(
                    f"the default id {event_id} of seq {seq} is already used by an earlier "
                    f"event in {self._directory} (an explicit id copied from this stream?)"
                )
        event = Event(
            event_id=event_id,
            stream=self._stream,
            seq=seq,
            time_ns=time_ns,
            recorded_at_ns=self._wall_clock(),
            type=type,
            version=version,
            task_id=task_id,
            payload=payload,
        )
        self._registry.validate_event(event)
        offset = self._size
        self._write(encode_record(event))
        self._ids[event.event_id] = offset
        self._last_seq = seq
        if self._batch_depth:
            self._unsynced = True
        else:
            self._sync()
        return event

    def _existing(
        self,
        event_id: str,
        type: str,
        version: int,
        payload: Mapping[str, Any],
        time_ns: int,
        task_id: str | None,
    ) -> Event:
        """The stored event with ``event_id``, if the new append asks for the same fact."""
        with (self._directory / LOG_FILE).open("rb") as f:
            f.seek(self._ids[event_id])
            stored = decode_record(f.readline()[:-1])
        wanted = Event(
            event_id=event_id,
            stream=self._stream,
            seq=stored.seq,
            time_ns=time_ns,
            recorded_at_ns=stored.recorded_at_ns,
            type=type,
            version=version,
            task_id=task_id,
            payload=payload,
        )
        if wanted != stored:
            differ = [
                name
                for name in ("type", "version", "task_id", "time_ns", "payload")
                if getattr(wanted, name) != getattr(stored, name)
            ]
            raise DuplicateEventError(
                f"event id {event_id} is already in {self._directory} at seq {stored.seq} with "
                f"a different {', '.join(differ)}; an id names one fact, nothing was written"
            )
        return stored

    @contextlib.contextmanager
    def batch(self) -> Iterator[None]:
        """Group appends under one fsync, done when the outermost batch exits.

        The events are acknowledged (durable) only then. Not a transaction: if the block raises,
        the events appended so far stay in the log (readers may already have seen them) and are
        still fsync'ed.
        """
        self._check_usable()
        self._batch_depth += 1
        try:
            yield
        finally:
            self._batch_depth -= 1
            if self._batch_depth == 0 and self._unsynced and self._broken is None:
                self._sync()

    def close(self) -> None:
        """Fsync anything pending, then release the file and the lock. Idempotent."""
        if self._closed:
            return
        try:
            if self._unsynced and self._broken is None:
                self._sync()
        finally:
            self._closed = True
            os.close(self._fd)
            os.close(self._lock_fd)

    def __enter__(self) -> EventLog:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else f"last_seq={self._last_seq}"
        return f"EventLog({str(self._directory)!r}, stream={self._stream!r}, {state})"

    def _check_usable(self) -> None:
        if self._closed:
            raise LogClosedError(f"event log {self._directory} is closed")
        if self._broken is not None:
            raise LogClosedError(
                f"event log {self._directory} refuses appends after a failed write "
                f"({self._broken}); reopen it to recover"
            )

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        try:
            while view:
                view = view[os.write(self._fd, view) :]
        except BaseException as exc:
            # A partial line left in place would turn the next append into mid-file corruption.
            try:
                os.ftruncate(self._fd, self._size)
            except OSError as cut_exc:
                self._broken = f"write failed ({exc!r}) and undoing it failed ({cut_exc!r})"
            raise
        self._size += len(data)

    def _sync(self) -> None:
        try:
            os.fsync(self._fd)
        except BaseException as exc:
            # After a failed fsync the kernel may drop the dirty pages and report success on the
            # next try, so nothing written since the last good fsync can be trusted any more.
            self._broken = f"fsync failed: {exc!r}"
            raise
        self._unsynced = False


def read_log(
    directory: Path | str,
    *,
    from_seq: int = 1,
    to_seq: int | None = None,
    upcast: bool = True,
) -> Iterator[Event]:
    """Yield the events of a log with ``from_seq <= seq <= to_seq``, in order. Never writes.

    Checks every record's checksum, stream and seq continuity up to ``to_seq`` (so a call
    raises :class:`CorruptLogError` rather than skip anything), but not payload schemas: those
    were checked at append. A torn tail is skipped with a :class:`TornTailWarning`, except an
    unterminated last line while a writer holds the lock: that is an append in progress.
    Events of an old schema version are upcast to their type's latest (``upcast=False`` gives
    them exactly as stored). Raises :class:`LogNotFoundError` at call time if there is no log.
    """
    directory = Path(directory)
    _check_seq_range(from_seq, to_seq)
    stream = _read_meta(directory)
    events = _read(directory, stream, from_seq, to_seq)
    return _upcast_all(events) if upcast else events


def follow_log(
    directory: Path | str,
    *,
    from_seq: int = 1,
    poll_interval: float = 0.05,
    idle_timeout: float | None = None,
    upcast: bool = True,
) -> Iterator[Event]:
    """Yield a log's events from ``from_seq`` on, waiting for new ones as a writer appends them.

    A reader that tails a live log: it takes no lock, reads only complete, checksum-valid
    records and checks them like :func:`read_log` (a damaged line followed by a valid record is
    a :class:`CorruptLogError`); an unfinished or damaged last line is waited on, since the
    writer may still be writing it or a restarted writer may cut it. Stops after
    ``idle_timeout`` seconds without a new event (never, if None).
    """
    directory = Path(directory)
    _check_seq_range(from_seq, None)
    if poll_interval <= 0:
        raise ValueError(f"poll_interval must be > 0, got {poll_interval!r}")
    stream = _read_meta(directory)
    events = _follow(directory / LOG_FILE, stream, from_seq, poll_interval, idle_timeout)
    return _upcast_all(events) if upcast else events


def _follow(
    path: Path, stream: str, from_seq: int, poll_interval: float, idle_timeout: float | None
) -> Iterator[Event]:
    position = (0, 0, 0)
    idle_since = time.monotonic()
    while True:
        scan = _Scan(path, stream, start=position)
        for event in scan:
            idle_since = time.monotonic()
            if event.seq >= from_seq:
                yield event
        position = (scan.end_offset, scan.end_line, scan.last_seq)
        if idle_timeout is not None and time.monotonic() - idle_since >= idle_timeout:
            return
        time.sleep(poll_interval)


def _upcast_all(events: Iterator[Event]) -> Iterator[Event]:
    upcast = default_upcaster().upcast
    for event in events:
        yield upcast(event)


def _check_seq_range(from_seq: object, to_seq: object) -> None:
    if isinstance(from_seq, bool) or not isinstance(from_seq, int) or from_seq < 1:
        raise ValueError(f"from_seq must be an integer >= 1, got {from_seq!r}")
    if to_seq is not None and (isinstance(to_seq, bool) or not isinstance(to_seq, int)):
        raise ValueError(f"to_seq must be an integer or None, got {to_seq!r}")


def _read(directory: Path, stream: str, from_seq: int, to_seq: int | None) -> Iterator[Event]:
    if to_seq is not None and to_seq < from_seq:
        return
    scan = _Scan(directory / LOG_FILE, stream, stop_after=to_seq)
    for event in scan:
        if event.seq >= from_seq:
            yield event
    tail = scan.torn_tail
    if tail is None:
        return
    if tail.lines == 1 and not tail.complete and _fs.is_locked(directory / LOCK_FILE):
        _log.debug("%s: unterminated last line while a writer is active; not yet written", tail)
        return
    _report(
        f"torn tail in {tail.path}: skipping {tail.length} byte(s) at byte offset {tail.offset} "
        f"(line {tail.line}; {tail.reason}); the file was not changed",
        stacklevel=4,
    )


def _cut_torn_tail(fd: int, tail: TornTail) -> None:
    # The only modification ever made to existing bytes, and never silent.
    _report(
        f"torn tail in {tail.path}: cut {tail.length} byte(s) at byte offset {tail.offset} "
        f"(line {tail.line}; {tail.reason}); these bytes were never acknowledged",
        stacklevel=5,
    )
    os.ftruncate(fd, tail.offset)
    os.fsync(fd)


def _report(message: str, *, stacklevel: int) -> None:
    _log.warning("%s", message)
    warnings.warn(message, TornTailWarning, stacklevel=stacklevel)


def _read_meta(directory: Path) -> str:
    """The stream named in ``meta.json``, after checking the directory is a log we can read."""
    meta_path = directory / META_FILE
    try:
        raw = meta_path.read_bytes()
    except (FileNotFoundError, NotADirectoryError):
        if not directory.is_dir():
            raise LogNotFoundError(
                f"no event log at {directory}: the directory does not exist"
            ) from None
        extra = f" (but {LOG_FILE} exists)" if (directory / LOG_FILE).exists() else ""
        raise LogNotFoundError(
            f"no event log at {directory}: {META_FILE} is missing{extra}"
        ) from None
    try:
        meta = json.loads(raw)
    except ValueError as exc:
        raise EventStoreError(f"{meta_path} is not valid JSON: {exc}") from exc
    if not isinstance(meta, dict) or meta.get("format") != LOG_FORMAT:
        found = meta.get("format") if isinstance(meta, dict) else None
        raise EventStoreError(
            f"{meta_path}: unsupported log format {found!r} (this code reads {LOG_FORMAT!r})"
        )
    stream = meta.get("stream")
    if not (isinstance(stream, str) and stream):
        raise EventStoreError(f"{meta_path}: 'stream' is missing or not a non-empty string")
    return stream
