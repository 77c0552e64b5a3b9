"""Committing runs to the fleet lake, each in one Delta transaction (:class:`LakeCommits`): from
tables, from events (streamed, in bounded memory), as read by the bag ingest, many at once, and
rows kept outside any run (a ledger's)."""

from __future__ import annotations

import dataclasses
import datetime as dt
import logging
import shutil
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, Final

import pyarrow as pa
import pyarrow.dataset as pds

from .. import _fs
from ..arrow import ENVELOPE_COLUMNS, event_schema, events_to_tables
from ..envelope import Event
from .common import _check_date, _check_name, _conform
from .digests import _chunks, stream_digest, table_digest
from .head import record_head
from .rewrite import LakeRewrites
from .run_digest import RunDigest
from .schema import (
    RUN_TYPE,
    TableLakeError,
    TableRaceLost,
    TableRun,
    _small_tables,
    _widen,
    run_parts,
    table_schema,
)
from .storage import CHUNK_EVENTS, _filesystem, _token
from .stream_file import _StreamFile, abandon
from .transactions import COMMIT_TRIES, _app_id, _transactions, stamp_version

_log = logging.getLogger(__name__)

#: DuckDB's memory for the derived tables of a streamed commit (bytes; it spills beyond), and
#: the most it is given when an operator that cannot spill needs more.
DERIVE_MEMORY: Final = 48 << 20
DERIVE_MEMORY_MAX: Final = 4 << 30


class LakeCommits(LakeRewrites):
    """The fleet lake, written: one transaction a run."""

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
        identity: Mapping[str, str] | None = None,
    ) -> TableRun:
        """Commit events (any versions; upcast to latest) as one run; ``date`` defaults to the
        UTC day of the first event's ``recorded_at_ns``."""
        first: list[Event] = []

        def remember(stream: Iterable[Event]) -> Iterable[Event]:
            for event in stream:
                if not first:
                    first.append(event)
                yield event

        tables = events_to_tables(remember(events), self.store)
        if date is None:
            if not first:
                raise TableLakeError("an empty run needs an explicit date")
            date = dt.datetime.fromtimestamp(first[0].recorded_at_ns / 1e9, dt.UTC).date()
        return self.commit_tables(
            tables,
            robot=robot,
            run=run,
            date=date,
            source=source,
            replace=replace,
            identity=identity,
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
        attachments: Mapping[str, str] | None = None,
        identity: Mapping[str, str] | None = None,
    ) -> TableRun:
        """Commit one table per event type as one run, in one transaction (see the module)."""
        run_info, parts = self._prepare(tables, robot, run, date, source, attachments, identity)
        self.create()
        return self._commit(run_info, parts, replace=replace)

    def _prepare(
        self,
        tables: Mapping[str, pa.Table],
        robot: str,
        run: str,
        date: str | dt.date,
        source: str,
        attachments: Mapping[str, str] | None,
        identity: Mapping[str, str] | None,
    ) -> tuple[TableRun, dict[str, pa.Table]]:
        """A run's description and its rows by ``type`` partition, checked."""
        _check_name("robot", robot)
        _check_name("run", run)
        day = _check_date(date)
        # By seq (a stable sort: a bag's streams keep their order among equal seqs), as the run's
        # rows are written and read back (run_parts, read_tables), so the digest recorded is the
        # digest of what a reader gets and read_events can check it.
        checked = {
            t: _conform(t, table, self.store).sort_by("seq") for t, table in sorted(tables.items())
        }
        run_info = TableRun(
            robot=robot,
            date=day,
            run=run,
            commit=_token(),
            rows={t: table.num_rows for t, table in checked.items()},
            digest=table_digest(checked),
            source=source,
            identity=dict(sorted((identity or {}).items())),
            attachments=dict(sorted((attachments or {}).items())),
        )
        return run_info, run_parts(checked, run_info, self.store)

    def commit_as_read(
        self,
        table: Any,
        tables: Mapping[str, pa.Table],
        *,
        robot: str,
        run: str,
        date: str | dt.date,
        source: str = "",
        attachments: Mapping[str, str] | None = None,
        identity: Mapping[str, str] | None = None,
        replacing: Sequence[str] = (),
        apps: Sequence[str] = (),
        stamps: Sequence[str] = (),
    ) -> TableRun:
        """Commit one run as decided from ``table`` (the version the caller read), in one
        transaction that also takes out the runs ``replacing`` names (of ``robot``: the run
        itself if it is there, runs merged into it). It carries the application transactions
        of the run, of each run it replaces, of its identity values and ``apps``, each one
        past its version in ``table``: if any commit since carried one of them, this one fails
        with :class:`TableRaceLost` and the caller reads again and decides anew (no retry
        here: what to commit depends on what is there). ``stamps``: application transactions
        set to the version after ``table``'s (:func:`stamp_version`), so of a thing stamped
        by several commits the latest commit's stamp is the highest. The bag ingest's commit."""
        from deltalake import CommitProperties, Transaction
        from deltalake.exceptions import CommitFailedError

        info, parts = self._prepare(tables, robot, run, date, source, attachments, identity)
        for other in replacing:
            _check_name("run", other)
        names = sorted({*replacing} - {run})
        txns = _transactions(table, info) + [
            Transaction(a, (table.transaction_version(a) or 0) + 1)
            for a in [*(_app_id(robot, r) for r in names), *apps]
        ]
        txns += [Transaction(a, stamp_version(table)) for a in stamps]
        commit = CommitProperties(app_transactions=txns)
        if not replacing:
            adds = self._write_files({k: [t] for k, t in parts.items()}, info.commit)
            try:
                table.create_write_transaction(
                    adds,
                    mode="append",
                    schema=table_schema(self.store),
                    partition_by=["type"],
                    commit_properties=commit,
                )
            except CommitFailedError as exc:
                landed = self.find(robot, run)
                if landed is not None and landed.commit == info.commit:
                    return landed  # it landed; its answer was lost
                self._delete_files(adds)
                raise TableRaceLost(f"{self.root}: run {robot}/{run} changed: {exc}") from exc
            _fs.durable_step()
            record_head(self, int(table.version()) + 1)
            return info
        try:
            self._overwrite_runs(table, robot, sorted({*replacing, run}), parts, info.commit, txns)
        except CommitFailedError as exc:
            landed = self.find(robot, run)
            if landed is not None and landed.commit == info.commit:
                return landed
            raise TableRaceLost(f"{self.root}: run {robot}/{run} changed: {exc}") from exc
        _fs.durable_step()
        record_head(self, int(table.version()) + 1)
        return info

    def commit_outside_runs(
        self, kind: str, info: TableRun, *, stamps: Sequence[str] = (), what: str = ""
    ) -> None:
        """Keep one row that belongs to no run's commit — a ledger's, in the partition ``kind``
        (``_<name>``, not ``_run``), described as a ``_run`` row describes a run (``info``: its
        identity and attachments carry what the ledger keeps; its commit token is the lake's) —
        appended in a transaction of its own, with ``stamps`` as :meth:`commit_as_read` sets
        them. What the rows mean is the ledger's (the bags' ingest records:
        :mod:`objsearch.pipeline.bags.ledger`); ``what`` names the row in an error."""
        from deltalake import CommitProperties, Transaction
        from deltalake.exceptions import CommitFailedError

        if not kind.startswith("_") or kind == RUN_TYPE:
            raise TableLakeError(f"a row outside any run goes in a partition _<name>, not {kind!r}")
        self.create()
        info = dataclasses.replace(info, commit=_token())
        column, row = _small_tables({}, info, self.store)[RUN_TYPE]
        part = _widen(kind, row, column, info, self.store)
        adds = self._write_files({kind: [part]}, info.commit)
        for attempt in range(COMMIT_TRIES):
            table = self.table()
            try:
                table.create_write_transaction(
                    adds,
                    mode="append",
                    schema=table_schema(self.store),
                    partition_by=["type"],
                    commit_properties=CommitProperties(
                        app_transactions=[Transaction(a, stamp_version(table)) for a in stamps]
                    ),
                )
                _fs.durable_step()
                record_head(self, int(table.version()) + 1)
                return
            except CommitFailedError:
                time.sleep(min(0.5, 0.01 * (attempt + 1)))
        self._delete_files(adds)
        raise TableLakeError(f"{self.root}: recording {what or kind} lost {COMMIT_TRIES} races")

    def _commit(
        self,
        info: TableRun,
        parts: Mapping[str, pa.Table],
        *,
        replace: bool,
        adds: list[Any] | None = None,
        table: Any | None = None,
    ) -> TableRun:
        from deltalake import CommitProperties
        from deltalake.exceptions import CommitFailedError, DeltaError

        # ``adds``: files written for an append (given, or written on the first try), kept
        # across retries
        for attempt in range(COMMIT_TRIES):
            table = self.table() if attempt or table is None else table
            existing = self.find(info.robot, info.run, table)
            if existing is not None and existing.commit == info.commit:
                # Our own commit landed though we heard a conflict (its answer was lost and
                # the store's retry of the conditional put found the version taken): its files
                # are the run's now, never to be deleted.
                self._maybe_compact(table)
                return existing
            if existing is not None and adds is not None:
                self._delete_files(adds)  # another writer committed the run first
                adds = None
            if existing is not None:
                if existing.date == info.date and self._same_content(existing, info.digest, table):
                    return existing  # the same run again: nothing to do
                if not replace:
                    raise TableLakeError(
                        f"{self.root} already holds run {info.run!r} of robot {info.robot!r} "
                        "with other content; pass replace=True to replace it"
                    )
                if not parts:  # a streamed commit raced another writer of this run
                    raise TableLakeError(
                        f"{self.root}: another writer committed run {info.run!r} of robot "
                        f"{info.robot!r} while this one was writing it; run the command again"
                    )
            commit_apps = _transactions(table, info)
            commit = CommitProperties(app_transactions=commit_apps)
            try:
                if existing is None:
                    if adds is None:
                        adds = self._write_files({k: [t] for k, t in parts.items()}, info.commit)
                    table.create_write_transaction(
                        adds,
                        mode="append",
                        schema=table_schema(self.store),
                        partition_by=["type"],
                        commit_properties=commit,
                    )
                else:
                    self._overwrite_runs(
                        table, info.robot, [info.run], parts, info.commit, commit_apps
                    )
            except CommitFailedError as exc:
                _log.debug(
                    "%s: commit of %s/%s lost a race (%s); again",
                    self.root,
                    info.robot,
                    info.run,
                    exc,
                )
                time.sleep(min(0.5, 0.01 * (attempt + 1)))
                continue
            except DeltaError as exc:  # e.g. "Invalid table version": a damaged log
                if adds is not None:
                    self._delete_files(adds)
                problems = self._log_problems(table)
                raise TableLakeError(
                    f"{self.root}: the table's log took no commit of run {info.robot}/{info.run} "
                    f"({str(exc).splitlines()[0][:200]})"
                    + (f": {'; '.join(problems)}" if problems else "")
                ) from exc
            _fs.durable_step()
            record_head(self, int(table.version()) + 1)
            self._maybe_compact(table)
            return info
        if adds is not None:
            self._delete_files(adds)
        raise TableLakeError(
            f"{self.root}: the commit of run {info.run!r} lost {COMMIT_TRIES} races with other "
            "writers; try again"
        )

    def commit_stream(
        self,
        open_events: Callable[[], Iterator[Event]],
        *,
        robot: str,
        run: str,
        date: str | dt.date | None = None,
        source: str = "",
        replace: bool = False,
        identity: Mapping[str, str] | None = None,
        table: Any | None = None,
    ) -> TableRun:
        """Commit the events ``open_events()`` yields as one run, reading them in chunks of
        :data:`CHUNK_EVENTS` and writing each type's file as they come, so a run of any length
        costs a bounded amount of memory (replacing a run still holds it whole). Calls
        ``open_events`` again when it must read the events twice (the run is there already:
        its digest is compared first). ``table``: the table as just loaded, if the caller has
        it (the lake exists)."""
        _check_name("robot", robot)
        _check_name("run", run)
        first = next(open_events(), None)
        if date is None:
            if first is None:
                raise TableLakeError("an empty run needs an explicit date")
            date = dt.datetime.fromtimestamp(first.recorded_at_ns / 1e9, dt.UTC).date()
        day = _check_date(date)
        if table is None:
            self.create()
            table = self.table()
        existing = self.find(robot, run, table)
        if existing is not None:
            digest, _ = stream_digest(open_events(), self.store)
            if existing.date == day and self._same_content(existing, digest, table):
                return existing
            if not replace:
                raise TableLakeError(
                    f"{self.root} already holds run {run!r} of robot {robot!r} with other "
                    "content; pass replace=True to replace it"
                )
            return self.commit_events(
                open_events(),
                robot=robot,
                run=run,
                date=day,
                source=source,
                replace=True,
                identity=identity,
            )
        info = TableRun(
            robot=robot,
            date=day,
            run=run,
            commit=_token(),
            rows={},
            digest="",
            source=source,
            identity=dict(sorted((identity or {}).items())),
        )
        info, adds = self._write_stream(open_events(), info)
        table.update_incremental()
        return self._commit(info, {}, replace=replace, adds=adds, table=table)

    def _write_stream(self, events: Iterable[Event], info: TableRun) -> tuple[TableRun, list[Any]]:
        """Write a run's files from its events in chunks; the run's description (rows, digest)
        and the files' add actions. The files are not part of the table until committed."""

        files: dict[str, _StreamFile] = {}
        digest = RunDigest()
        rows: dict[str, int] = {}
        try:
            for chunk in _chunks(events, self.store):
                for event_type, table in chunk.items():
                    digest.add(event_type, table)
                    rows[event_type] = rows.get(event_type, 0) + table.num_rows
                    if event_type not in files:
                        files[event_type] = _StreamFile(self, event_type, event_type, info.commit)
                    files[event_type].add(_widen(event_type, table, event_type, info, self.store))
            adds = [files[t].close() for t in sorted(files)]
        except BaseException:
            abandon(self, files.values())
            raise
        info = dataclasses.replace(info, rows=rows, digest=digest.hexdigest())
        # The chunks' buffers back to the system before DuckDB reads the files (Arrow's pool
        # keeps freed memory for reuse otherwise).
        pa.default_memory_pool().release_unused()
        try:
            derived = self._derive({t: f.rel for t, f in files.items()})
        except BaseException:
            self._delete_files(adds)
            raise
        # Widened a slice at a time, as the events were: a whole derived table widened at once
        # (eq4_updates: ~280 k rows at 1 M events) was the commit's peak of memory.
        small = _small_tables(derived, info, self.store)
        del derived
        written: list[_StreamFile] = []
        try:
            for kind, (column, part) in sorted(small.items()):
                written.append(_StreamFile(self, kind, column, info.commit))
                for start in range(0, max(part.num_rows, 1), CHUNK_EVENTS):
                    piece = part.slice(start, CHUNK_EVENTS)
                    written[-1].add(_widen(kind, piece, column, info, self.store))
                adds.append(written[-1].close())
                small[kind] = (column, part.slice(0, 0))  # its rows back to the pool
        except BaseException:
            abandon(self, written)
            self._delete_files(adds)
            raise
        return info, adds

    def _derive(self, files: Mapping[str, str]) -> dict[str, pa.Table]:
        """The derived tables of one run from its data files just written (``files``: event
        type → path in the table), read back a batch at a time in bounded memory: DuckDB gets
        :data:`DERIVE_MEMORY` and spills to a private temp folder beyond it; an operator that
        cannot spill and needs more gets twice as much, and so on."""
        import duckdb

        from ..derived import derive_views
        from ..sql_limits import progress_bar_off

        memory = DERIVE_MEMORY
        while True:
            spill = tempfile.mkdtemp(prefix="objsearch-derive-")
            con = duckdb.connect(
                ":memory:",
                config={
                    "threads": 1,
                    "memory_limit": f"{memory}B",
                    "temp_directory": spill,
                    "preserve_insertion_order": False,
                },
            )
            try:
                progress_bar_off(con)  # lake add prints its own line
                envelope = ", ".join(f'"{f.name}"' for f in ENVELOPE_COLUMNS)
                for event_type in self.store.registry.types:
                    if event_type in files:
                        con.execute(
                            f'CREATE VIEW "{event_type}" AS SELECT robot, date, run, {envelope}, '
                            f'"{event_type}".* FROM {self._file_source(con, files[event_type])}'
                        )
                    else:
                        empty = event_schema(event_type, self.store).empty_table()
                        con.register(f"_empty_{event_type}", empty)
                        con.execute(
                            f'CREATE VIEW "{event_type}" AS SELECT NULL::VARCHAR AS robot, '
                            "NULL::DATE AS date, NULL::VARCHAR AS run, * "
                            f'FROM "_empty_{event_type}"'
                        )
                return derive_views(con, self.store)
            except duckdb.OutOfMemoryException as exc:
                if memory >= DERIVE_MEMORY_MAX:
                    raise
                _log.info("derived tables need more than %d MB (%s); again", memory >> 20, exc)
                memory *= 2
            finally:
                con.close()
                shutil.rmtree(spill, ignore_errors=True)

    def _file_source(self, con: Any, rel: str) -> str:
        """What DuckDB reads one of this commit's data files as: ``read_parquet`` (projection
        pushed into the Parquet file) when local, an Arrow dataset of the object when remote."""
        if self.remote:
            fs, base = _filesystem(self.uri)
            name = "_file_" + rel.replace("/", "_").replace("=", "_").replace(".", "_")
            con.register(name, pds.dataset(f"{base}/{rel}", format="parquet", filesystem=fs))
            return f'"{name}"'
        path = str(Path(self.uri) / rel).replace("'", "''")
        return f"read_parquet('{path}', hive_partitioning = false)"

    def commit_many(self, runs: Sequence[tuple[TableRun, Mapping[str, pa.Table]]]) -> None:
        """Commit new runs (none in the lake yet) in one transaction: the migration's and the
        benchmarks' bulk path. Raises if one is there already."""
        from deltalake import CommitProperties
        from deltalake.exceptions import CommitFailedError

        if not runs:
            return
        self.create()
        table = self.table()
        apps = []
        for info, _ in runs:
            if self.find(info.robot, info.run, table):
                raise TableLakeError(f"{self.root}: run {info.robot}/{info.run} is already there")
            apps += _transactions(table, info)
        by_kind: dict[str, list[pa.Table]] = {}
        for _, parts in runs:
            for kind, part in parts.items():
                by_kind.setdefault(kind, []).append(part)
        adds = self._write_files(by_kind, _token())
        try:
            for attempt in range(COMMIT_TRIES):
                try:
                    table.create_write_transaction(
                        adds,
                        mode="append",
                        schema=table_schema(self.store),
                        partition_by=["type"],
                        commit_properties=CommitProperties(app_transactions=apps),
                    )
                    _fs.durable_step()
                    record_head(self, int(table.version()) + 1)
                    return
                except CommitFailedError:
                    # e.g. a compaction's claim (a metadata change) came first: read again
                    time.sleep(min(0.5, 0.01 * (attempt + 1)))
                    table = self.table()
                    found = [self.find(i.robot, i.run, table) for i, _ in runs]
                    if all(
                        f is not None and f.commit == i.commit
                        for f, (i, _) in zip(found, runs, strict=True)
                    ):
                        return  # it landed; its answer was lost
                    there = [i for f, (i, _) in zip(found, runs, strict=True) if f is not None]
                    if there:
                        raise TableLakeError(
                            f"{self.root}: run {there[0].robot}/{there[0].run} is already there"
                        ) from None
                    apps = [a for info, _ in runs for a in _transactions(table, info)]
            raise TableLakeError(
                f"{self.root}: the commit of {len(runs)} runs lost {COMMIT_TRIES} races; try again"
            )
        except BaseException:
            self._delete_files(adds)
            raise
