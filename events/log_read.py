"""Reading a log: :func:`read_log` (a range of seqs, every record checked), :func:`follow_log` (a
live log tailed as its writer appends) and :func:`read_log_after` (the events after a checked
position, the prefix not read). Readers never write and take no lock; a torn tail is skipped and
reported, silently while a writer holds the lock (:func:`is_being_written`). Kept apart from the
writer (:mod:`.log`), which needs none of it: both check records with the same pass
(:mod:`.scan`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from . import _fs
from .envelope import Event
from .fold_read import RecordFold, fold_records
from .log_files import (
    LOCK_FILE,
    LOG_FILE,
    Durable,
    LogMeta,
    LogPosition,
    TornTail,
    read_durable,
    read_meta,
)
from .log_position import check_position
from .log_torn_tail import _report
from .scan import _Cursor, _Scan
from .schemas import SchemaRegistry
from .store import Store

# The logger of the log before it was split: what callers and tests filter torn-tail reports by.
_log = logging.getLogger("objsearch.events.log")

__all__ = ["LogEvents", "follow_log", "is_being_written", "read_log", "read_log_after"]


def read_log(
    directory: Path | str,
    *,
    from_seq: int = 1,
    to_seq: int | None = None,
    upcast: bool = True,
    store: Store,
) -> Iterator[Event]:
    """Yield the events of a log with ``from_seq <= seq <= to_seq``, in order. Never writes.

    Checks every record (checksum chain, stream, seq continuity, known type and version, time
    order) up to ``to_seq`` and, reading to the end, that the log reaches its durable high-water
    mark, so a call raises :class:`CorruptLogError` rather than skip anything — but not payload
    schemas: those were checked at append. An unterminated last fragment is skipped with a
    :class:`TornTailWarning`, silently while a writer holds the lock (an append in progress).
    Events of an old schema version are upcast to their type's latest (``upcast=False`` gives
    them exactly as stored). ``store`` knows the types, versions and upcasters (the product's is
    :data:`objsearch.agent.catalogue.STORE`). Raises :class:`LogNotFoundError` at call time if
    there is no log.
    """
    directory = Path(directory)
    _check_seq_range(from_seq, to_seq)
    meta = read_meta(directory)
    durable = read_durable(directory)
    return LogEvents(directory, meta, durable, from_seq, to_seq, store, upcast)


class LogEvents(Iterator[Event]):
    """What :func:`read_log` returns: an iterator of the log's events; or, handed whole to
    :func:`~.projection.fold` before its first event is taken, a fold from the log's records
    (:mod:`.fold_read`: the same checks, no event built per record) when the projection can
    take them."""

    def __init__(
        self,
        directory: Path,
        meta: LogMeta,
        durable: Durable | None,
        from_seq: int,
        to_seq: int | None,
        store: Store,
        upcast: bool,
    ) -> None:
        self._args = (directory, meta, durable, from_seq, to_seq, store, upcast)
        self._events: Iterator[Event] | None = None

    def _started(self) -> Iterator[Event]:
        events = self._events
        if events is None:
            directory, meta, durable, from_seq, to_seq, store, upcast = self._args
            events = self._events = _read(
                directory, meta, durable, from_seq, to_seq, store.registry,
                store if upcast else None,
            )  # fmt: skip
        return events

    def __next__(self) -> Event:
        return next(self._started())

    def __iter__(self) -> LogEvents:
        return self

    def close(self) -> None:
        """Stop reading (as a generator's ``close``)."""
        close = getattr(self._events, "close", None)
        if close is not None:
            close()

    def fold_into(
        self,
        projection: object,
        until_seq: int | None,
        apply_event: Callable[[Event], None],
    ) -> bool:
        """Fold the whole log into ``projection`` from its records, if it can take them
        (:class:`~.fold_read.RecordFold`) and no event was taken yet; False: fold events."""
        directory, meta, durable, from_seq, to_seq, store, upcast = self._args
        if (
            self._events is not None
            or from_seq != 1
            or to_seq is not None
            or not upcast
            or not isinstance(projection, RecordFold)
        ):
            return False
        self._events = iter(())
        tail = fold_records(
            directory / LOG_FILE, meta, durable, store, projection, until_seq, apply_event
        )
        if tail is not None:
            _report_tail(directory, tail, stacklevel=5)  # fold's caller
        return True


def follow_log(
    directory: Path | str,
    *,
    from_seq: int = 1,
    poll_interval: float = 0.05,
    idle_timeout: float | None = None,
    upcast: bool = True,
    store: Store,
) -> Iterator[Event]:
    """Yield a log's events from ``from_seq`` on, waiting for new ones as a writer appends them.

    A reader that tails a live log: it takes no lock, reads only complete records and checks
    them like :func:`read_log` (any damaged complete line is a :class:`CorruptLogError`); an
    unterminated last line is waited on, since the writer may still be writing it. Stops after
    ``idle_timeout`` seconds without a new event (never, if None).
    """
    directory = Path(directory)
    _check_seq_range(from_seq, None)
    if poll_interval <= 0:
        raise ValueError(f"poll_interval must be > 0, got {poll_interval!r}")
    meta = read_meta(directory)
    events = _follow(
        directory / LOG_FILE, meta, from_seq, poll_interval, idle_timeout, store.registry
    )
    return _upcast_all(events, store) if upcast else events


def _follow(
    path: Path,
    meta: LogMeta,
    from_seq: int,
    poll_interval: float,
    idle_timeout: float | None,
    registry: SchemaRegistry,
) -> Iterator[Event]:
    position = _Cursor(checksum=meta.genesis)
    idle_since = time.monotonic()
    while True:
        scan = _Scan(path, meta, registry=registry, start=position)
        for event in scan:
            idle_since = time.monotonic()
            if event.seq >= from_seq:
                yield event
        position = scan.at
        if idle_timeout is not None and time.monotonic() - idle_since >= idle_timeout:
            return
        time.sleep(poll_interval)


def _upcast_all(events: Iterator[Event], store: Store) -> Iterator[Event]:
    upcast = store.upcaster.upcast
    for event in events:
        yield upcast(event)


def _check_seq_range(from_seq: object, to_seq: object) -> None:
    if isinstance(from_seq, bool) or not isinstance(from_seq, int) or from_seq < 1:
        raise ValueError(f"from_seq must be an integer >= 1, got {from_seq!r}")
    if to_seq is not None and (isinstance(to_seq, bool) or not isinstance(to_seq, int)):
        raise ValueError(f"to_seq must be an integer or None, got {to_seq!r}")


def _read(
    directory: Path,
    meta: LogMeta,
    durable: Durable | None,
    from_seq: int,
    to_seq: int | None,
    registry: SchemaRegistry,
    upcast_with: Store | None,
) -> Iterator[Event]:
    if to_seq is not None and to_seq < from_seq:
        return
    scan = _Scan(directory / LOG_FILE, meta, registry=registry, durable=durable, stop_after=to_seq)
    if upcast_with is None:
        for event in scan:
            if event.seq >= from_seq:
                yield event
    else:
        upcaster = upcast_with.upcaster
        upcast = upcaster.upcast
        latest = upcaster.latest_versions
        for event in scan:
            if event.seq >= from_seq:
                # Most events are at their type's latest version: no call for those.
                yield event if event.version >= latest.get(event.type, 0) else upcast(event)
    tail = scan.torn_tail
    if tail is not None:
        _report_tail(directory, tail, stacklevel=6)  # the reader's caller


def _report_tail(directory: Path, tail: TornTail, *, stacklevel: int) -> None:
    if is_being_written(directory):
        _log.debug("%s: unterminated last line while a writer is active; not yet written", tail)
        return
    _report(
        f"torn tail in {tail.path}: skipping {tail.length} byte(s) at byte offset {tail.offset} "
        f"(line {tail.line}; {tail.reason}); the file was not changed",
        stacklevel=stacklevel,
    )


def is_being_written(directory: Path | str) -> bool:
    """Whether a writer holds the log in ``directory`` open (read-only check)."""
    directory = Path(directory)
    return _fs.is_locked(directory / LOG_FILE) or _fs.is_locked(directory / LOCK_FILE)


def read_log_after(
    directory: Path | str,
    position: LogPosition,
    *,
    upcast: bool = True,
    store: Store,
) -> Iterator[Event]:
    """The events after ``position`` (checked to be where it says), verified like
    :func:`read_log` from there on; the prefix is not read (a restart from a snapshot)."""
    directory = Path(directory)
    meta = read_meta(directory)
    check_position(directory, meta, position)
    durable = read_durable(directory)
    scan = _Scan(
        directory / LOG_FILE,
        meta,
        registry=store.registry,
        durable=durable if durable is not None and durable.seq > position.seq else None,
        start=position,
    )
    events: Iterator[Event] = iter(scan)
    return _upcast_all(events, store) if upcast else events
