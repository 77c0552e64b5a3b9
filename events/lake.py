"""The analytics lake: typed Parquet per event type, partitioned by robot / date / run.

Layout (Hive-style, readable by DuckDB, polars, pyarrow and any Parquet reader)::

    LAKE/robot=<robot>/date=<YYYY-MM-DD>/run=<run>/<event_type>.parquet
    LAKE/robot=<robot>/date=<YYYY-MM-DD>/run=<run>/_run.json      what the run holds
    LAKE/robot=<robot>/date=<YYYY-MM-DD>/run=<run>/_derived/<name>.v<version>.parquet
    LAKE/.staging/                                               runs being written

A run is committed whole and atomically: its files are written and fsync'ed in a staging
directory, then the directory is renamed into place, so a reader (or a crash) sees all of a run
or none of it. Committing the same content again is a no-op (its digest matches), so re-running
an import never duplicates; different content for an existing run needs ``replace=True``.

Each event table is written sorted by ``seq`` in row groups of 128 Ki rows, so a reader
filtering on ``seq`` can skip row groups by their min/max statistics. Next to the events, a
commit writes the run's derived tables (:mod:`objsearch.events.derived`: per-task summaries and
the Eq. 4 update rows), computed from that run's tables alone; they are not part of the digest
(they are a function of it), and committing the same content again writes any that are missing
or of an older version, which is how a lake written by older code is upgraded
(:meth:`Lake.upgrade` does it for every run).

The lake is where anything that produces events lands: :func:`compact_log` seals an event log
into it, and other importers (e.g. ROS bags) call :meth:`Lake.commit_events` or
:meth:`Lake.commit_tables` directly.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import os
import re
import shutil
import uuid
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import pyarrow as pa
import pyarrow.parquet as pq

from . import _fs
from .arrow import event_schema, events_to_tables, tables_to_events
from .derived import DERIVED_DIR, DERIVED_TABLES, DerivedTable, derive_run
from .envelope import Event
from .errors import EventStoreError
from .log import LOCK_FILE, read_log

LAKE_FORMAT: Final = "objsearch.lake/1"
RUN_FILE: Final = "_run.json"
STAGING: Final = ".staging"
_NAME: Final = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
#: Rows per Parquet row group: small enough that a seq range skips most of a 1 M-event run and
#: that DuckDB has several units of work per file, large enough to compress well.
ROW_GROUP_ROWS: Final = 1 << 17


class LakeError(EventStoreError):
    """The lake cannot do what was asked (bad name, run exists with other content, …)."""


@dataclass(frozen=True, slots=True)
class RunInfo:
    """One committed run: where it is and what it holds (the contents of its ``_run.json``)."""

    robot: str
    date: str
    run: str
    path: Path
    rows: Mapping[str, int]  # event type → rows
    digest: str
    source: str

    @property
    def events(self) -> int:
        return sum(self.rows.values())

    def missing_derived(self) -> list[DerivedTable]:
        """Derived tables this run lacks at their current version (older code wrote it)."""
        return [d for d in DERIVED_TABLES if not d.path(self.path).is_file()]


class Lake:
    """A directory of committed runs. Cheap to create; nothing is read until asked."""

    def __init__(self, root: Path | str) -> None:
        self.root = Path(root)

    def __repr__(self) -> str:
        return f"Lake({str(self.root)!r})"

    # -- reading --------------------------------------------------------------------------------

    def runs(self) -> list[RunInfo]:
        """Every committed run, sorted by (robot, date, run)."""
        found = [
            _read_run_file(p) for p in sorted(self.root.glob(f"robot=*/date=*/run=*/{RUN_FILE}"))
        ]
        return sorted(found, key=lambda r: (r.robot, r.date, r.run))

    def find(self, robot: str, run: str) -> RunInfo | None:
        """The run ``run`` of ``robot``, whatever its date, or None."""
        matches = [
            _read_run_file(p) for p in self.root.glob(f"robot={robot}/date=*/run={run}/{RUN_FILE}")
        ]
        if len(matches) > 1:
            raise LakeError(f"{self.root}: run {run!r} of robot {robot!r} is under two dates")
        return matches[0] if matches else None

    def files(self, event_type: str) -> list[Path]:
        """The Parquet files of ``event_type`` across all runs."""
        return sorted(self.root.glob(f"robot=*/date=*/run=*/{event_type}.parquet"))

    def read_events(self, run: RunInfo) -> list[Event]:
        """Every event of one committed run, as :class:`Event` (latest versions), by (stream, seq)."""
        # ParquetFile, not read_table: the latter would add the hive partition columns.
        return tables_to_events(
            pq.ParquetFile(p).read() for p in sorted(run.path.glob("*.parquet"))
        )

    def read_tables(self, run: RunInfo) -> dict[str, pa.Table]:
        """The event tables of one committed run as stored (one per type present)."""
        return {p.stem: pq.ParquetFile(p).read() for p in sorted(run.path.glob("*.parquet"))}

    def upgrade(self) -> list[RunInfo]:
        """Write the derived tables every run lacks (a lake written by older code); returns the
        runs upgraded. Idempotent, and each file appears atomically, so readers never see half."""
        upgraded = []
        for info in self.runs():
            if info.missing_derived():
                _write_derived(info.path, self.read_tables(info), info)
                upgraded.append(info)
        return upgraded

    def event_types(self) -> list[str]:
        """Event types with at least one file in the lake."""
        return sorted({p.stem for p in self.root.glob("robot=*/date=*/run=*/*.parquet")})

    # -- writing --------------------------------------------------------------------------------

    def commit_events(
        self,
        events: Iterable[Event],
        *,
        robot: str,
        run: str,
        date: str | dt.date | None = None,
        source: str = "",
        replace: bool = False,
    ) -> RunInfo:
        """Commit events (any versions; upcast to latest) as one run.

        ``date`` defaults to the UTC day of the first event's ``recorded_at_ns``.
        """
        first: list[Event] = []

        def remember(stream: Iterable[Event]) -> Iterable[Event]:
            for event in stream:
                if not first:
                    first.append(event)
                yield event

        tables = events_to_tables(remember(events))
        if date is None:
            if not first:
                raise LakeError("an empty run needs an explicit date")
            date = dt.datetime.fromtimestamp(first[0].recorded_at_ns / 1e9, dt.UTC).date()
        return self.commit_tables(
            tables, robot=robot, run=run, date=date, source=source, replace=replace
        )

    def commit_tables(
        self,
        tables: Mapping[str, pa.Table],
        *,
        robot: str,
        run: str,
        date: str | dt.date,
        source: str = "",
        replace: bool = False,
    ) -> RunInfo:
        """Commit one table per event type as one run, atomically. Tables must match
        :func:`event_schema` of their type (columns may be cast, not missing)."""
        _check_name("robot", robot)
        _check_name("run", run)
        day = _check_date(date)
        checked = {t: _conform(t, table) for t, table in sorted(tables.items())}
        digest = _digest(checked)
        existing = self.find(robot, run)
        if existing is not None:
            if existing.digest == digest and existing.date == day:
                # The same run again: nothing to do but add derived tables it may lack.
                if existing.missing_derived():
                    _write_derived(existing.path, checked, existing)
                return existing
            if not replace:
                raise LakeError(
                    f"{existing.path} already holds run {run!r} of robot {robot!r} with other "
                    "content; pass replace=True to replace it"
                )
        final = self.root / f"robot={robot}" / f"date={day}" / f"run={run}"
        staging = self.root / STAGING / uuid.uuid4().hex
        _fs.make_dirs(staging)
        try:
            for event_type, table in checked.items():
                _write_parquet(staging / f"{event_type}.parquet", table.sort_by("seq"))
            derived = derive_run(checked, robot=robot, date=day, run=run)
            _fs.make_dirs(staging / DERIVED_DIR)
            for spec in DERIVED_TABLES:
                _write_parquet(spec.path(staging), derived[spec.name])
            _fs.fsync_dir(staging / DERIVED_DIR)
            manifest = {
                "format": LAKE_FORMAT,
                "robot": robot,
                "date": day,
                "run": run,
                "rows": {t: table.num_rows for t, table in checked.items()},
                "digest": digest,
                "source": source,
            }
            _fs.write_atomic(staging / RUN_FILE, _json_bytes(manifest))
            _fs.fsync_dir(staging)
            _fs.make_dirs(final.parent)
            if existing is not None:
                trash = self.root / STAGING / f"old-{uuid.uuid4().hex}"
                os.rename(existing.path, trash)
                _fs.fsync_dir(existing.path.parent)
                os.rename(staging, final)
                shutil.rmtree(trash)
            else:
                os.rename(staging, final)  # fails if a concurrent commit got there first
            _fs.fsync_dir(final.parent)
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise
        return _read_run_file(final / RUN_FILE)


def compact_log(
    log_dir: Path | str,
    lake: Lake,
    *,
    robot: str,
    run: str | None = None,
    date: str | dt.date | None = None,
    replace: bool = False,
) -> RunInfo:
    """Seal an event log into the lake as one run (``run`` defaults to the log's stream).

    Only a sealed log is compacted: one whose writer has closed it (its lock is free), so the
    run in the lake is the whole stream. Compacting it again after more appends needs
    ``replace=True``; compacting it unchanged is a no-op.
    """
    log_dir = Path(log_dir)
    if _fs.is_locked(log_dir / LOCK_FILE):
        raise LakeError(
            f"event log {log_dir} is being written (its lock is held{_fs.lock_holder_hint(log_dir / LOCK_FILE)}); "
            "close the writer before compacting it"
        )
    events = read_log(log_dir)
    first = next(events, None)
    if first is None:
        raise LakeError(f"event log {log_dir} is empty; there is nothing to compact")

    def all_events() -> Iterable[Event]:
        yield first
        yield from events

    return lake.commit_events(
        all_events(),
        robot=robot,
        run=run or first.stream,
        date=date,
        source=f"event log {log_dir.resolve()}",
        replace=replace,
    )


def _conform(event_type: str, table: pa.Table) -> pa.Table:
    schema = event_schema(event_type)
    missing = [name for name in schema.names if name not in table.column_names]
    extra = [name for name in table.column_names if name not in schema.names]
    if missing or extra:
        raise LakeError(
            f"table for {event_type} does not match its schema: missing {missing}, extra {extra}"
        )
    try:
        return table.select(schema.names).cast(schema)
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError) as exc:
        raise LakeError(f"table for {event_type} cannot be cast to its schema: {exc}") from exc


def _write_derived(run_dir: Path, tables: Mapping[str, pa.Table], info: RunInfo) -> None:
    """Add the missing derived tables to a committed run, each atomically (tmp file, rename)."""
    derived = derive_run(tables, robot=info.robot, date=info.date, run=info.run)
    _fs.make_dirs(run_dir / DERIVED_DIR)
    for spec in info.missing_derived():
        final = spec.path(run_dir)
        tmp = final.with_name(f".{final.name}.{uuid.uuid4().hex}.tmp")
        try:
            _write_parquet(tmp, derived[spec.name])
            os.rename(tmp, final)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
        # An older version of the same table is dead weight once the current one is in place.
        for stale in final.parent.glob(f"{spec.name}.v*.parquet"):
            if stale != final:
                stale.unlink()
    _fs.fsync_dir(run_dir / DERIVED_DIR)


def _write_parquet(path: Path, table: pa.Table) -> None:
    pq.write_table(table, path, compression="zstd", row_group_size=ROW_GROUP_ROWS)
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _digest(tables: Mapping[str, pa.Table]) -> str:
    h = hashlib.sha256()
    for event_type, table in tables.items():
        h.update(event_type.encode() + b"\0")
        sink = pa.BufferOutputStream()
        with pa.ipc.new_stream(sink, table.schema) as writer:
            writer.write_table(table)
        h.update(sink.getvalue().to_pybytes())
    return "sha256:" + h.hexdigest()


def _json_bytes(doc: Mapping[str, Any]) -> bytes:
    return json.dumps(doc, indent=1, sort_keys=True, ensure_ascii=False).encode() + b"\n"


def _read_run_file(path: Path) -> RunInfo:
    try:
        doc = json.loads(path.read_bytes())
    except (OSError, ValueError) as exc:
        raise LakeError(f"{path}: cannot read the run manifest: {exc}") from exc
    if not isinstance(doc, dict) or doc.get("format") != LAKE_FORMAT:
        raise LakeError(f"{path}: not a {LAKE_FORMAT} run manifest")
    return RunInfo(
        robot=doc["robot"],
        date=doc["date"],
        run=doc["run"],
        path=path.parent,
        rows=dict(doc["rows"]),
        digest=doc["digest"],
        source=doc["source"],
    )


def _check_name(what: str, value: str) -> None:
    if not (isinstance(value, str) and _NAME.match(value)):
        raise LakeError(
            f"{what} name {value!r} must start with a letter or digit and hold only letters, "
            "digits, '.', '_' and '-' (it becomes a directory name)"
        )


def _check_date(value: str | dt.date) -> str:
    try:
        day = value if isinstance(value, dt.date) else dt.date.fromisoformat(value)
    except (TypeError, ValueError):
        raise LakeError(f"date {value!r} is not an ISO date (YYYY-MM-DD)") from None
    return day.isoformat()
