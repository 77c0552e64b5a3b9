"""``lake add``: an agent's sealed event log into the fleet lake as one run."""

from __future__ import annotations

import datetime as dt
import logging
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

from .. import _fs
from ..envelope import Event
from ..errors import EventStoreError
from ..log_files import LOCK_FILE, read_meta
from ..log_read import read_log
from ..store import Store
from .fleet import TableLake
from .schema import TableLakeError, TableRun

_log = logging.getLogger(__name__)


def _valid(log_dir: Path, store: Store) -> Iterator[Event]:
    """The log's events, each checked against the schema of the version it was written in,
    then upcast. ``read_log`` checks records (checksums, envelopes), not payloads: a record
    another writer made may lack a field its schema requires, which the table would read back
    as null (or not take at all), so the lake refuses it, naming it."""
    registry, upcast = store.registry, store.upcaster.upcast
    for event in read_log(log_dir, upcast=False, store=store):
        try:
            registry.validate_event(event)
        except EventStoreError as exc:
            raise TableLakeError(
                f"event log {log_dir}: the record of seq {event.seq} does not match its schema "
                f"({exc}); the lake takes only events valid under their schemas"
            ) from exc
        yield upcast(event)


def add_log(
    log_dir: Path | str,
    lake: TableLake,
    *,
    robot: str,
    run: str | None = None,
    date: str | dt.date | None = None,
    replace: bool = False,
    progress: Callable[[Iterable[Event]], Iterable[Event]] | None = None,
) -> TableRun:
    """Seal an event log into the fleet lake as one run (``run`` defaults to the log's stream),
    without reading any other run. Only a sealed log is added (its writer closed it); adding
    it again unchanged is a no-op, after more appends it needs ``replace``. ``progress`` wraps
    the events of each full read of the log (the CLI's progress line)."""
    log_dir = Path(log_dir)
    if _fs.is_locked(log_dir / LOCK_FILE):
        raise TableLakeError(
            f"event log {log_dir} is being written (its lock is held{_fs.lock_holder_hint(log_dir / LOCK_FILE)}); "
            "close the writer before compacting it"
        )
    events = read_log(log_dir, store=lake.store)
    first = next(events, None)
    if first is None:
        raise TableLakeError(f"event log {log_dir} is empty; there is nothing to compact")
    run = run or first.stream
    identity = {"first_event_id": first.event_id}
    meta = read_meta(log_dir)
    if meta.run_id is not None:
        identity["run_id"] = meta.run_id
    lake.create()
    table = lake.table()
    # A lake whose runs' records and table disagree takes no run: the next compaction would
    # make the loss permanent. One whose `_run` file is damaged does (it costs those runs).
    unreadable = lake.check_runs(table)
    for _, why in unreadable:
        _log.warning("%s: the records of the runs it holds cannot be read: %s", lake.root, why)
    lake.check_writable(table)
    for other in lake.holding(identity, table):
        if (other.robot, other.run) != (robot, run):
            raise TableLakeError(
                f"event log {log_dir} (agent run {meta.run_id or first.stream}) is already in "
                f"the lake as run {other.run!r} of robot {other.robot!r} (from {other.source}); "
                "adding it again would count its events twice"
            )

    reads = 0

    def open_events() -> Iterator[Event]:
        nonlocal reads
        reads += 1
        events = _valid(log_dir, lake.store)
        if progress is None or reads == 1:  # the first read peeks at one event
            return events
        return iter(progress(events))

    return lake.commit_stream(
        open_events,
        robot=robot,
        run=run,
        date=date,
        source=f"event log {log_dir.resolve()}",
        replace=replace,
        identity=identity,
        table=table,
    )
