"""The fleet lake: every run in one Delta Lake table, one transaction per run.

Layout (a local folder, or ``s3://bucket/prefix``)::

    LAKE/events/_delta_log/…                 the table's transaction log (JSON + checkpoints)
    LAKE/events/type=<event type>/*.parquet  rows of that event type, every run
    LAKE/events/type=derived.<name>.v<N>/    a derived table's rows (per-run summaries)
    LAKE/events/type=_run/                   one row a run: what it holds (digest, rows, source)

One table, partitioned by ``type``; the run is a column (``robot``, ``date``, ``run``,
``commit``), so the number of files does not grow with the number of runs once the table is
compacted (:meth:`TableLake.compact`; ``lake add`` compacts when the table holds more than
:data:`COMPACT_AT_FILES` files). Each event type's payload is one struct column named after the
type (``detection.mask_area``); the envelope columns are shared. Because a run's events, its
derived tables and its ``_run`` row are added in **one Delta transaction**, a reader (or a
crash) sees all of a run or none of it, with no staging folder, rename or lock of ours:

* **commit**: an append carrying the Delta *application transaction* ``objsearch/<robot>/<run>``.
  Two writers committing the same run at once conflict on it (the table's optimistic
  concurrency); the loser re-reads and finds the run there — the same content is a no-op,
  other content needs ``replace``. Writers of different runs never conflict (blind appends);
  a commit that loses a race with another transaction is retried (:data:`COMMIT_TRIES`).
* **replace** / **remove**: one transaction, bumping the run's application-transaction version,
  that removes every data file that may hold the run's rows (by the log's statistics) and adds
  their other rows, in their order, with the run's new rows after them (ours, not delta-rs's
  overwrite or delete: those name their files without a hash).
* **damage**: every data file this module writes is **content-addressed** — named after the
  SHA-256 of its bytes, ``type=<kind>/part-<token>-<sha256>.zstd.parquet`` (a file written from
  memory is hashed before it is stored; a streamed one is hashed as it is written under a
  temporary name in the partition's folder, then renamed — locally a rename and an fsync of the
  folder, on S3 a copy and a delete — before the commit names it), so any reader finds each
  file's hash in the table's log alone. Compaction is ours (:meth:`TableLake._optimize`) and
  writes content-addressed files too, after checking each input (a damaged one stays as it is:
  rewritten, its damage would get a fresh hash). Every query (:meth:`TableLake.scan`;
  ``replay`` and ``where`` check a run's digest instead) leaves out, naming it, a file that is
  missing, has another size than the log records, or — content-addressed — whose bytes do not
  hash to its name's SHA-256. A file is hashed once per change of its ``stat`` identity (size,
  mtime, ctime, inode), remembered in a verification cache outside the lake
  (:mod:`.lake_table_verified`): a query costs one ``stat`` a file once this machine has hashed
  the files, and the first query after a file appears or changes hashes that file (about as
  long as reading it). Unhashed files (written by code before content-addressed names, or by
  delta-rs: its compaction, overwrite and delete name their files without a hash) get the cheap
  check only (no ``PAR1`` at both ends: cut); ``compact`` rewrites them content-addressed. On
  S3 a query hashes nothing (a first sight would download every object once per machine: see
  ``docs/analytics.md``). ``verify`` hashes every content-addressed file in full, whatever the
  cache says, decodes every file (page checksums on) and compares its rows with the log's.
* **the log against the runs' records**: each ``_run`` row records its run's rows per event
  type and derived table, and each commit records the version it made (:data:`HEAD_FILE`), so
  ``query``, ``lake ls``, ``lake add`` and ``lake compact`` refuse a table whose log lost an
  ``add``, a whole commit or its newest commits (:meth:`TableLake.check_runs`), and ``verify``
  counts each run's rows; a damaged ``_run`` file costs its runs, not the lake
  (:meth:`TableLake.read_runs`).

Any Delta reader reads the table: DuckDB's ``delta_scan`` (the ``delta`` extension),
``polars.scan_delta``, ``deltalake.DeltaTable(…).to_pyarrow_dataset()``; ``docs/analytics.md``.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import functools
import hashlib
import io
import itertools
import json
import logging
import math
import os
import random
import re
import shutil
import tempfile
import time
import uuid
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, NamedTuple

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.dataset as pds
import pyarrow.fs as pafs
import pyarrow.parquet as pq

from . import _fs
from .arrow import (
    ENVELOPE_COLUMNS,
    event_schema,
    events_to_tables,
    payload_schema,
    tables_to_events,
)
from .derived import PARTITION_NAMES, derive_run, derived_tables
from .envelope import Event
from .errors import EventStoreError
from .lake import (
    ROW_GROUP_ROWS,
    LakeError,
    _check_date,
    _check_name,
    _conform,
    parquet_problem,
)
from .lake_table_verified import Identity, VerifiedFiles, sha256_file
from .log_files import LOCK_FILE, read_meta
from .log_read import read_log
from .run_digest import DIGEST_PREFIX, RunDigest, digest_version, values_digest
from .store import Store, shipped

TABLE_FORMAT: Final = "objsearch.lake/2"
TABLE_DIR: Final = "events"
RUN_TYPE: Final = "_run"
#: Rows of bags' ingest records kept outside any run (:meth:`TableLake.record_bag`).
BAG_TYPE: Final = "_bag"
#: The struct column holding a ``_run`` row's description of its run.
RUN_COLUMN: Final = "run_info"
BASE_COLUMNS: Final = (
    pa.field("robot", pa.string(), nullable=False),
    pa.field("date", pa.date32(), nullable=False),
    pa.field("run", pa.string(), nullable=False),
    pa.field("commit", pa.string(), nullable=False),
    pa.field("type", pa.string(), nullable=False),
)
_RUN_STRUCT: Final = pa.struct(
    [
        ("format", pa.string()),
        ("digest", pa.string()),
        ("rows", pa.string()),  # JSON: event type → rows
        ("source", pa.string()),
        ("identity", pa.string()),  # JSON
        ("attachments", pa.string()),  # JSON: name → text
        ("committed_at_ns", pa.int64()),
    ]
)
#: How often a commit that lost a race with another transaction is tried again.
COMMIT_TRIES: Final = 50
#: The table property a compaction sets before it plans (its claim: ``<ns>-<token>``). A
#: change of the table's metadata fails every transaction that read the table before it, and
#: a compaction plans from exactly its claim's version, so of two compactions that overlap
#: only one commits (see :meth:`TableLake.compact`).
COMPACTION_CLAIM: Final = "objsearch.compaction"
#: ``lake add`` leaves compaction to another writer whose claim is younger than this (s).
COMPACTION_CLAIM_FRESH_S: Final = 120.0
#: ``lake add`` compacts the table once it holds more data files than this.
COMPACT_AT_FILES: Final = 256
#: Files compaction aims for (bytes); a table of a fleet's year is a few thousand of them.
TARGET_FILE_BYTES: Final = 256 << 20
#: A data file the lake writes is named after the SHA-256 of its bytes (content-addressed):
#: ``type=<kind>/part-<token>-<64 hex>.zstd.parquet``. Files written by code before this, which
#: let delta-rs compact and replace, have no hash in their name ("unhashed"); ``lake compact``
#: rewrites them.
_HASHED_NAME: Final = re.compile(r"-([0-9a-f]{64})\.zstd\.parquet$")
_log = logging.getLogger(__name__)


class TableLakeError(LakeError):
    """The fleet lake cannot do what was asked."""


class TableRaceLost(TableLakeError):
    """Another commit changed what :meth:`TableLake.commit_as_read` decided from: read again."""


@dataclass(frozen=True, slots=True)
class TableRun:
    """One committed run of the fleet lake (its ``_run`` row)."""

    robot: str
    date: str
    run: str
    commit: str
    rows: Mapping[str, int]
    digest: str
    source: str
    identity: Mapping[str, str] = dataclasses.field(default_factory=dict)
    attachments: Mapping[str, str] = dataclasses.field(default_factory=dict)
    #: Rows of each derived table's partition (``derived.<name>.v<N>`` → rows) the commit
    #: wrote, as its ``_run`` row records them beside ``rows`` (empty: a run committed before
    #: they were recorded; its derived rows cannot be counted against the table).
    #: Not compared: they follow from the events (a run as committed equals the run read back).
    derived_rows: Mapping[str, int] = dataclasses.field(default_factory=dict, compare=False)

    @property
    def events(self) -> int:
        return sum(self.rows.values())

    @property
    def label(self) -> str:
        return f"{self.robot}/{self.run}"


@dataclass(frozen=True, slots=True)
class DataFile:
    """One data file of the table's current version, as its log records it."""

    path: str  # relative to the table
    kind: str  # the ``type`` partition
    size: int
    rows: int | None


@dataclass(frozen=True, slots=True)
class TableCheck:
    files: int
    bytes: int
    runs: int
    damaged: list[tuple[str, str]]  # (file, why)
    #: What does not agree with the runs' records: (a run ``robot/run``, or ``_delta_log``; why)
    runs_damaged: list[tuple[str, str]] = dataclasses.field(default_factory=list)


def _nullable(kind: pa.DataType) -> pa.DataType:
    if pa.types.is_struct(kind):
        return pa.struct([pa.field(f.name, _nullable(f.type)) for f in kind])
    if pa.types.is_list(kind):
        return pa.list_(_nullable(kind.value_type))
    return kind


def payload_struct(event_type: str, store: Store) -> pa.StructType:
    envelope = {f.name for f in ENVELOPE_COLUMNS}
    return pa.struct(
        [
            pa.field(f.name, _nullable(f.type))
            for f in event_schema(event_type, store)
            if f.name not in envelope
        ]
    )


def derived_column(name: str) -> str:
    return f"derived_{name}"


def derived_kind(name: str, version: int) -> str:
    return f"derived.{name}.v{version}"


@functools.cache  # per store (by identity)
def derived_structs(store: Store) -> dict[str, pa.StructType]:
    """The columns of each derived table (what :func:`derive_run` gives for an empty run)."""
    out = derive_run({}, robot="r", date="1970-01-01", run="r", store=store)
    return {
        name: pa.struct([pa.field(f.name, _nullable(f.type)) for f in t.schema])
        for name, t in out.items()
    }


@functools.cache  # per store (by identity)
def table_schema(store: Store) -> pa.Schema:
    """The fleet table's columns: run, envelope, one struct per event type and derived table,
    and the ``_run`` row's description."""
    fields = [*BASE_COLUMNS, *(pa.field(f.name, f.type) for f in ENVELOPE_COLUMNS)]
    fields += [pa.field(t, payload_struct(t, store)) for t in store.registry.types]
    fields += [pa.field(derived_column(n), s) for n, s in derived_structs(store).items()]
    fields.append(pa.field(RUN_COLUMN, _RUN_STRUCT))
    return pa.schema(fields)


@functools.cache  # per store (by identity)
def _events_schema(store: Store) -> pa.Schema:
    """:func:`table_schema` without the derived tables' columns."""
    fields = [*BASE_COLUMNS, *(pa.field(f.name, f.type) for f in ENVELOPE_COLUMNS)]
    fields += [pa.field(t, payload_struct(t, store)) for t in store.registry.types]
    fields.append(pa.field(RUN_COLUMN, _RUN_STRUCT))
    return pa.schema(fields)


def read_schema(store: Store, kinds: frozenset[str]) -> pa.Schema:
    """The columns a reader of files of ``kinds`` (``type`` partitions) types them with:
    :func:`table_schema`, less the derived tables' columns unless a derived kind is read
    (their types come from running the derived tables' SQL on an empty run: a DuckDB start,
    ~50 MB, that ``replay`` or ``where`` from a lake run has no use for)."""
    if kinds <= {*store.registry.types, RUN_TYPE, BAG_TYPE}:
        return _events_schema(store)
    return table_schema(store)


def is_table_lake(root: Path | str) -> bool:
    """Whether ``root`` holds a fleet lake (a Delta table at ``root/events``)."""
    text = str(root)
    if "://" in text:
        from deltalake import DeltaTable

        return bool(DeltaTable.is_deltatable(f"{text.rstrip('/')}/{TABLE_DIR}", storage_options()))
    return (Path(root) / TABLE_DIR / "_delta_log").is_dir()


#: How long an object-store request may go without an answer before it is tried again, and how
#: often (Arrow's S3 client; delta-rs gets the same time-out).
S3_REQUEST_TIMEOUT_S: Final = 120.0
S3_CONNECT_TIMEOUT_S: Final = 30.0
S3_ATTEMPTS: Final = 10


def storage_options() -> dict[str, str]:
    """Object-store settings from the standard environment: ``AWS_ENDPOINT_URL`` (e.g. a local
    S3 server), ``AWS_ACCESS_KEY_ID``, ``AWS_SECRET_ACCESS_KEY``, ``AWS_REGION`` — read by
    delta-rs itself; only what it cannot infer is added (plain HTTP for an ``http://``
    endpoint), and time-outs as long as Arrow's client gets."""
    options = {
        "timeout": f"{S3_REQUEST_TIMEOUT_S:.0f}s",
        "connect_timeout": f"{S3_CONNECT_TIMEOUT_S:.0f}s",
    }
    if os.environ.get("AWS_ENDPOINT_URL", "").startswith("http://"):
        options["AWS_ALLOW_HTTP"] = "true"
    return options


class TableLake:
    """The fleet lake at ``root`` (a folder or an ``s3://`` URI). Cheap to create."""

    def __init__(self, root: Path | str, *, store: Store | None = None) -> None:
        #: What the lake's events are: their types, Arrow schemas, upcasters, derived tables.
        self.store = store or shipped()
        text = str(root)
        self.remote = "://" in text
        self.root: Path | str = text.rstrip("/") if self.remote else Path(root)
        self.uri = (
            f"{text.rstrip('/')}/{TABLE_DIR}"
            if self.remote
            else str(Path(root).absolute() / TABLE_DIR)
        )
        self.options = storage_options() if self.remote else {}
        #: Data files :meth:`scan` hashed (not found in the verification cache) so far.
        self.hashed = 0

    def __repr__(self) -> str:
        return f"TableLake({str(self.root)!r})"

    # -- the table ------------------------------------------------------------------------------

    def exists(self) -> bool:
        return is_table_lake(self.root)

    def table(self) -> Any:
        """The Delta table at its latest version (``deltalake.DeltaTable``)."""
        from deltalake import DeltaTable
        from deltalake.exceptions import DeltaError, TableNotFoundError

        try:
            return DeltaTable(self.uri, storage_options=self.options)
        except TableNotFoundError:
            raise TableLakeError(
                f"no fleet lake at {self.root} (no Delta table at {self.uri})"
            ) from None
        except DeltaError as exc:  # a commit file of the table's log cut, garbled or missing
            raise TableLakeError(
                f"the table's log of the fleet lake at {self.root} is damaged and cannot be "
                f"read: {str(exc).splitlines()[0][:300]}"
            ) from exc

    def create(self) -> None:
        """Create the (empty) table if it does not exist; safe to race with other writers."""
        from deltalake import write_deltalake

        if self.exists():
            return
        if not self.remote:
            _fs.make_dirs(Path(self.uri).parent)
        from deltalake import CommitProperties, Transaction

        empty = table_schema(self.store).empty_table()
        try:
            write_deltalake(
                self.uri,
                empty,
                mode="ignore",
                partition_by=["type"],
                name="objsearch events",
                description=TABLE_FORMAT,
                storage_options=self.options,
                commit_properties=CommitProperties(
                    app_transactions=[
                        Transaction(IDENTITY_INDEX_APP, 1),
                        Transaction(STAMP_INDEX_APP, 1),
                    ]
                ),
            )
            _fs.durable_step()
        except Exception:
            if not self.exists():
                raise

    # -- reading --------------------------------------------------------------------------------

    def data_files(self, table: Any | None = None) -> list[DataFile]:
        """The data files of the table's current version."""
        table = self.table() if table is None else table
        actions = pa.table(table.get_add_actions(flatten=True))
        kinds = actions.column("partition.type").to_pylist()
        rows = (
            actions.column("num_records").to_pylist()
            if "num_records" in actions.column_names
            else [None] * len(kinds)
        )
        return [
            DataFile(str(p), str(k), int(s), None if n is None else int(n))
            for p, k, s, n in zip(
                actions.column("path").to_pylist(),
                kinds,
                actions.column("size_bytes").to_pylist(),
                rows,
                strict=True,
            )
        ]

    def files_dataset(self, files: Sequence[DataFile], *, checksums: bool = False) -> pds.Dataset:
        """An Arrow dataset of some of the table's data files, typed as the table, read through
        Arrow's own S3 client with the sizes the table's log records (no request a file before
        the read). Not ``to_pyarrow_dataset``: delta-rs's Python file-system handler can abort
        the interpreter at exit ("terminate called without an active exception": a writer of
        the S3 writers' test died so, once it had read a run's ``_run`` row). ``checksums``:
        check each page's CRC as it is read."""
        fs, base = _filesystem(self.uri) if self.remote else (pafs.LocalFileSystem(), self.uri)
        parquet = pds.ParquetFileFormat(
            default_fragment_scan_options=pds.ParquetFragmentScanOptions(
                page_checksum_verification=checksums
            )
        )
        fragments = [
            parquet.make_fragment(
                f"{base}/{f.path}",
                fs,
                partition_expression=pc.field("type") == f.kind,
                file_size=f.size,
            )
            for f in files
        ]
        # A file this module wrote holds its own type's columns only; one delta-rs wrote (no
        # hash in its name) may hold every column of the table.
        if all(file_sha256(f.path) is not None for f in files):
            schema = read_schema(self.store, frozenset(f.kind for f in files))
        else:
            schema = table_schema(self.store)
        return pds.FileSystemDataset(fragments, schema, parquet, fs)

    def _dataset(self, table: Any, kinds: Sequence[str]) -> pds.Dataset:
        where = [("type", "in", list(kinds))]
        if self.remote:
            return self.files_dataset([f for f in self.data_files(table) if f.kind in kinds])
        # Local files through Arrow's own file system: delta-rs's Python file-system handler
        # can abort the interpreter at exit ("terminate called without an active exception").
        return pds.dataset(
            table.file_uris(file_pruning_predicate=where),
            schema=read_schema(self.store, frozenset(kinds)),
            format="parquet",
            partitioning=pds.partitioning(pa.schema([("type", pa.string())]), flavor="hive"),
            partition_base_dir=self.uri,
        )

    def runs(self, table: Any | None = None) -> list[TableRun]:
        """Every committed run, sorted by (robot, date, run); a ``_run`` file that cannot be
        read raises :class:`TableLakeError` naming it (:meth:`read_runs` reads past it)."""
        return self._runs(self.table() if table is None else table, None)

    def _runs(self, table: Any, where: pc.Expression | None) -> list[TableRun]:
        """The runs ``where`` picks; a ``_run`` file that cannot be read raises, unless the
        log's statistics show it holds one run's record only and ``where`` does not pick
        that run (a damaged record of another run costs this question nothing)."""
        found, unreadable = self.read_runs(table, where)
        unreadable = self._may_match(table, unreadable, where)
        if unreadable:
            raise _unreadable_records(self.root, unreadable)
        return found

    def _may_match(
        self, table: Any, unreadable: list[tuple[DataFile, str]], where: pc.Expression | None
    ) -> list[tuple[DataFile, str]]:
        """Those of ``unreadable`` that may hold a row ``where`` picks: each, unless the log
        records one robot and one run for it (min = max) and a row of them fails ``where``
        (a ``where`` on other columns: each)."""
        if not unreadable or where is None:
            return unreadable
        actions = pa.table(table.get_add_actions(flatten=True)).to_pylist()
        one: dict[str, tuple[str, str]] = {}
        for a in actions:
            robot, run = a.get("min.robot"), a.get("min.run")
            if None not in (robot, run) and (robot, run) == (a.get("max.robot"), a.get("max.run")):
                one[str(a["path"])] = (robot, run)
        kept = []
        for f, why in unreadable:
            if f.path in one:
                robot, run = one[f.path]
                try:
                    probe = pa.table({"robot": [robot], "run": [run]})
                    if not probe.filter(where).num_rows:
                        continue
                except (pa.ArrowException, TypeError, ValueError):
                    pass  # ``where`` reads other columns: it may pick the file's row
            kept.append((f, why))
        return kept

    def read_runs(
        self,
        table: Any | None = None,
        where: pc.Expression | None = None,
        *,
        files: Sequence[DataFile] | None = None,
        checked: bool = False,
    ) -> tuple[list[TableRun], list[tuple[DataFile, str]]]:
        """The ``_run`` rows (sorted by robot, date, run) of every ``_run`` file that reads, and
        each one that does not, with why: missing, of another size than the log records, not
        the bytes its name's SHA-256 records (locally: :meth:`scan`'s checks), not decoding
        (page checksums on), or holding a row that is no run's record. One damaged file costs
        the runs it records, not the lake's. ``files``: those ``_run`` files only (default:
        all of ``table``'s); ``checked``: they passed :meth:`scan`'s checks already."""
        table = self.table() if table is None else table
        if files is None:
            files = [f for f in self.data_files(table) if f.kind == RUN_TYPE]
        good, bad = (list(files), []) if checked else self._check_files(files, hashes=True)
        columns = ["robot", "date", "run", "commit", RUN_COLUMN]

        def read(some: list[DataFile]) -> list[TableRun]:
            if not some:
                return []
            dataset = self.files_dataset(some, checksums=True)
            return [_run_of(r) for r in dataset.to_table(columns=columns, filter=where).to_pylist()]

        try:
            found = read(good)
        except (OSError, pa.ArrowException, *_RECORD_ERRORS):
            found = []  # one at a time, to name the file that does not read
            for f in good:
                try:
                    found += read([f])
                except (OSError, pa.ArrowException) as exc:
                    bad.append((f, f"{f.path} does not decode: {str(exc)[:300]}"))
                except _RECORD_ERRORS as exc:
                    bad.append((f, f"{f.path} holds a row that is no run's record ({exc!r})"))
        return sorted(found, key=lambda r: (r.robot, r.date, r.run)), bad

    def find(self, robot: str, run: str, table: Any | None = None) -> TableRun | None:
        table = self.table() if table is None else table
        if table.transaction_version(_app_id(robot, run)) is None:
            return None  # never committed (every commit of a run sets it): no row to read
        where = (pc.field("robot") == robot) & (pc.field("run") == run)
        found, unreadable = self.read_runs(table, where)
        unreadable = self._may_match(table, unreadable, where)
        if unreadable:
            raise _unreadable_records(
                self.root, unreadable, f"the record of run {robot}/{run} cannot be read"
            )
        if len(found) > 1:  # cannot happen through this class: its commits conflict
            raise TableLakeError(f"{self.root}: run {run!r} of robot {robot!r} is there twice")
        return found[0] if found else None

    def holding(self, identity: Mapping[str, str], table: Any | None = None) -> list[TableRun]:
        """The runs whose recorded identity shares a value with ``identity``: the ``_run``
        rows whose identity text holds one of the values are decoded, no other."""
        wanted = {(k, v) for k, v in identity.items() if v}
        if not wanted:
            return []
        table = self.table() if table is None else table
        if table.transaction_version(IDENTITY_INDEX_APP) is not None and all(
            table.transaction_version(_identity_app(k, v)) is None for k, v in wanted
        ):
            return []  # no run ever committed any of these values: no row to read
        text = pc.field(RUN_COLUMN, "identity")
        where: pc.Expression | None = None
        for _, value in wanted:
            hit = pc.match_substring(text, json.dumps(value))
            where = hit if where is None else where | hit
        found, unreadable = self.read_runs(table, where)
        if unreadable:
            raise _unreadable_records(
                self.root,
                unreadable,
                "whether a run of the lake holds this recording cannot be told, a record of "
                "its runs cannot be read",
            )
        return [r for r in found if wanted & set(r.identity.items())]

    def read_tables(self, run: TableRun, table: Any | None = None) -> dict[str, pa.Table]:
        """The event tables of one run, one per type, as :func:`event_schema` types them."""
        table = self.table() if table is None else table
        dataset = self._dataset(table, sorted(run.rows))
        rows = dataset.to_table(
            columns=[*(f.name for f in ENVELOPE_COLUMNS), "type", *sorted(run.rows)],
            filter=(pc.field("robot") == run.robot)
            & (pc.field("run") == run.run)
            & (pc.field("commit") == run.commit),
        )
        envelope = [f.name for f in ENVELOPE_COLUMNS]
        out = {}
        for event_type in sorted(run.rows):
            part = rows.filter(pc.field("type") == event_type).sort_by("seq")
            payload = part.column(event_type).combine_chunks()
            schema = event_schema(event_type, self.store)
            columns = [part.column(n) for n in envelope] + [
                payload.field(f.name) for f in schema if f.name not in envelope
            ]
            out[event_type] = pa.Table.from_arrays(columns, names=schema.names).cast(schema)
        return out

    def read_events(self, run: TableRun, table: Any | None = None) -> list[Event]:
        """The run's events, upcast, after checking that its rows read back as committed: as
        many of each type and the digest its ``_run`` row records (a data file missing, cut or
        altered under the log raises :class:`TableLakeError` naming the run, never a shorter
        run)."""
        try:
            tables = self.read_tables(run, table)
        except (OSError, pa.ArrowException) as exc:  # a file gone, cut, or not Parquet
            raise TableLakeError(
                f"{self.root}: run {run.robot}/{run.run} could not be read: {exc}"
            ) from exc
        rows = {event_type: part.num_rows for event_type, part in tables.items()}
        if rows != dict(run.rows) or not self._digest_holds(run, tables):
            raise TableLakeError(
                f"{self.root}: run {run.robot}/{run.run} is damaged: its rows do not read back "
                f"as committed (rows {rows}, committed {dict(run.rows)}); `objsearch lake verify "
                f"{self.root}` names the files"
            )
        upcast = self.store.upcaster.upcast
        return [upcast(e) for e in tables_to_events(tables.values(), self.store)]

    def _digest_holds(self, run: TableRun, tables: Mapping[str, pa.Table]) -> bool:
        """Whether ``tables`` (the run's rows as read back) have the digest its ``_run`` row
        records. A version-1 digest (Arrow IPC bytes, runs committed before version 2) is
        checked on the rows as read and, failing that, on the rows rebuilt from their Python
        values under the schema of the version they record, as that commit built and hashed
        them: rows read back from Parquet may hold equal values in other buffers (a null
        struct's children gain validity bitmaps), and a type may have gained a version (and
        columns) since."""
        version = digest_version(run.digest)
        if version == 2:
            return table_digest(tables) == run.digest
        if version != 1:
            return False
        if ipc_digest(tables) == run.digest:
            return True
        # Per type, the hashes of its rows as that commit may have hashed them: as read back
        # (a bag's commit hashed rows it had read back) and as built from Python values (a
        # log's), each under the schema of the version they record; one of each type's must do.
        candidates: dict[str, set[str]] = {}
        for event_type, part in tables.items():
            versions = pc.unique(part.column("version")).to_pylist()
            if len(versions) > 1:
                return False  # a commit wrote one version a type (the latest, then)
            try:
                schema = committed_schema(event_type, versions[0] if versions else None, self.store)
                read = part.select(schema.names).cast(schema)
                built = pa.Table.from_pylist(read.to_pylist(), schema=schema)
            except (KeyError, EventStoreError, pa.ArrowException):
                return False
            candidates[event_type] = {_ipc_type_digest(read), _ipc_type_digest(built)}
        types = sorted(candidates)
        return any(
            _combine(dict(zip(types, choice, strict=True))) == run.digest
            for choice in itertools.product(*(sorted(candidates[t]) for t in types))
        )

    def _same_content(self, existing: TableRun, digest: str, table: Any) -> bool:
        """Whether the committed run ``existing`` holds the rows whose (version-2) ``digest``
        is given: a run committed under version 1 is read back and hashed again."""
        if existing.digest == digest:
            return True
        if digest_version(existing.digest) == 2 or not digest.startswith(DIGEST_PREFIX):
            return False
        try:
            tables = self.read_tables(existing, table)
        except (OSError, pa.ArrowException):
            return False
        return table_digest(tables) == digest

    def scan(
        self, table: Any | None = None, *, hashes: bool = True
    ) -> tuple[list[DataFile], list[tuple[DataFile, str]]]:
        """The data files readers may read, and those they must leave out: missing, of another
        size than the log records, or — a content-addressed file (:func:`file_sha256`) — whose
        bytes do not hash to the SHA-256 its name records; an unhashed file is checked for
        ``PAR1`` at both ends only. A hashed file is hashed when this machine first sees it
        and again only once its ``stat`` identity changes (:mod:`.lake_table_verified`: a
        cache outside the lake), so a query costs one ``stat`` a file once the files were
        seen; the number of files does not grow with the runs once the table is compacted.
        ``hashes=False``: no hashing (:meth:`verify` hashes every file itself). On S3 nothing
        is checked here (the object store checks what it serves; ``lake verify`` hashes)."""
        files = self.data_files(table)
        good, bad = self._check_files(files, hashes=hashes, forget_others=True)
        if hashes and not self.remote:
            unhashed = sum(1 for f in good if file_sha256(f.path) is None)
            if unhashed:
                _log.warning(
                    "%s: %d data file(s) have no hash in their name (written before data files "
                    "were content-addressed): checked for size and PAR1 ends only; `objsearch "
                    "lake compact --lake %s` rewrites them content-addressed",
                    self.root,
                    unhashed,
                    self.root,
                )
        return good, bad

    def _check_files(
        self, files: Sequence[DataFile], *, hashes: bool, forget_others: bool = False
    ) -> tuple[list[DataFile], list[tuple[DataFile, str]]]:
        """:meth:`scan`'s checks of ``files``: those that pass, and the others with why.
        ``forget_others``: ``files`` are all the table's (the cache forgets any other)."""
        if self.remote:
            return list(files), []
        good, bad = [], []
        base = Path(self.uri)
        cache = VerifiedFiles(self.uri) if hashes else None
        for f in files:
            path = base / f.path
            try:
                st = path.stat()
            except OSError as exc:
                bad.append((f, f"{f.path}: {exc.strerror or exc}"))
                continue
            if st.st_size != f.size:
                bad.append(
                    (f, f"{f.path} has {st.st_size} bytes, the table's log records {f.size}")
                )
                continue
            expected = file_sha256(f.path)
            if expected is None or cache is None:
                problem = parquet_problem(path)
                if problem is not None:
                    bad.append((f, f"{f.path}: {problem}"))
                    continue
                good.append(f)
                continue
            identity = Identity.of(st)
            if not cache.known(f.path, identity, expected):
                hashed_at = time.time_ns()
                problem = self._hash_problem(f, path)
                if problem is not None:
                    bad.append((f, problem))
                    continue
                cache.remember(f.path, identity, expected, hashed_at)
            good.append(f)
        if cache is not None:
            if forget_others:
                cache.keep_only(f.path for f in files)
            cache.save()
        return good, bad

    def _hash_problem(self, f: DataFile, path: Path) -> str | None:
        """Why a local content-addressed file's bytes are not the ones written, or None."""
        self.hashed += 1
        try:
            actual = sha256_file(path)
        except OSError as exc:
            return f"{f.path}: {exc.strerror or exc}"
        return _hash_mismatch(f, actual)

    def verify(
        self, progress: Callable[[list[DataFile]], Iterable[DataFile]] | None = None
    ) -> TableCheck:
        """Read every byte: hash each content-addressed data file in full (whatever the
        verification cache says) and compare with the hash its name records, decode each
        data file in full (page checksums on) and compare its rows with the log's statistics
        (plus the checks of :meth:`scan`); then count each run's rows of each type in the
        decoded files against what its ``_run`` row records (``runs_damaged``: a run short of
        rows — a commit file's ``add`` removed — or rows no run records), and check the log
        (:meth:`_log_problems`) and each run's application transactions. A ``_run`` file that
        does not read is a damaged file like any other; the check goes on without its runs.
        Changes nothing. ``progress`` wraps the files as they are decoded (the CLI's progress
        line)."""

        table = self.table()
        good, bad = self.scan(table, hashes=False)
        size = 0
        checked = 0
        verified: list[DataFile] = []
        #: rows of each (robot, run, commit, type) the decoded files hold
        held: dict[tuple[str, str, str, str], int] = {}
        for f in progress(good) if progress else good:
            try:
                if self.remote:
                    fs, base = _filesystem(self.uri)
                    with fs.open_input_file(f"{base}/{f.path}") as fh:
                        data = fh.read()
                else:
                    data = (Path(self.uri) / f.path).read_bytes()
            except OSError as exc:
                bad.append((f, f"{f.path} cannot be read: {exc}"))
                continue
            mismatch = _hash_mismatch(f, hashlib.sha256(data).hexdigest())
            if mismatch is not None:
                bad.append((f, mismatch))
                continue
            try:
                decoded = pq.ParquetFile(
                    pa.BufferReader(data), page_checksum_verification=True
                ).read()
            except (OSError, pa.ArrowException) as exc:
                bad.append((f, f"{f.path} does not decode: {exc}"))
                continue
            if f.rows is not None and decoded.num_rows != f.rows:
                bad.append(
                    (f, f"{f.path} holds {decoded.num_rows} rows, the table's log records {f.rows}")
                )
                continue
            checked += 1
            size += f.size
            verified.append(f)
            if decoded.num_rows and {"robot", "run", "commit"} <= set(decoded.column_names):
                per_commit = decoded.group_by(["robot", "run", "commit"]).aggregate(
                    [([], "count_all")]
                )
                for robot, run, commit, n in zip(*per_commit.to_pydict().values(), strict=True):
                    key = (robot, run, commit, f.kind)
                    held[key] = held.get(key, 0) + n
        runs, unreadable = self.read_runs(
            table, files=[f for f in verified if f.kind == RUN_TYPE], checked=True
        )
        bad += unreadable
        problems = [("_delta_log", p) for p in self._log_problems(table)]
        problems += [("_delta_log", p) for p in self._empty_commits()]
        damaged_kinds = {f.kind for f, _ in bad}
        problems += _run_problems(runs, held, damaged_kinds, RUN_TYPE in damaged_kinds)
        problems += [(r, p) for r, p in self._transaction_problems(table, runs)]
        return TableCheck(
            files=checked - len(unreadable),
            bytes=size,
            runs=len(runs),
            damaged=[(f.path, why) for f, why in bad],
            runs_damaged=problems,
        )

    # -- the runs' records against the table ---------------------------------------------------

    def check_runs(self, table: Any | None = None) -> list[tuple[DataFile, str]]:
        """The ``_run`` files that cannot be read (:meth:`read_runs`), after checking the table
        against the runs' records from the table's log and the ``_run`` rows' ``rows`` alone
        (no event read; each distinct record parsed once): each partition's rows, by the log's
        statistics, against what the records add up to — events, derived tables, one ``_run``
        row a run — no run recorded twice, no commit after the checkpoint emptied
        (:meth:`_empty_commits`), and the table's version against the latest this lake
        recorded committing (:data:`HEAD_FILE`). Raises
        :class:`TableLakeError` saying what disagrees: a commit file edited (an ``add``
        removed) or the newest deleted, whose rows no query would then read. What it cannot
        see: a ``_run`` file that cannot be read hides its runs' rows from the count (only
        more rows than the readable records name is then allowed); derived rows of a run
        committed before they were recorded; a log edited so the totals still agree (two
        edits; ``lake verify`` counts each run's rows). The read paths' guard: ``query``,
        ``lake ls``, ``lake add``, ``lake compact``."""
        table = self.table() if table is None else table
        files = self.data_files(table)
        good, unreadable = self._check_files([f for f in files if f.kind == RUN_TYPE], hashes=True)
        columns = {
            "robot": pc.field("robot"),
            "run": pc.field("run"),
            "rows": pc.field(RUN_COLUMN, "rows"),
        }

        def tally(some: list[DataFile]) -> tuple[dict[str, int], list[str]]:
            if not some:
                return _tally(pa.table({k: pa.array([], pa.string()) for k in columns}), self.store)
            rows = self.files_dataset(some, checksums=True).to_table(columns=columns)
            return _tally(rows, self.store)

        try:
            recorded, twice = tally(good)
        except (OSError, pa.ArrowException, *_RECORD_ERRORS):
            readable = []  # one at a time, to name the file that does not read
            for f in good:
                try:
                    tally([f])
                    readable.append(f)
                except (OSError, pa.ArrowException) as exc:
                    unreadable.append((f, f"{f.path} does not decode: {str(exc)[:300]}"))
                except _RECORD_ERRORS as exc:
                    unreadable.append(
                        (f, f"{f.path} holds a row that is no run's record ({exc!r})")
                    )
            recorded, twice = tally(readable)
        problems = self._log_problems(table, writing=False) + self._empty_commits()
        problems += [f"run {label} is recorded more than once" for label in twice]
        problems += _count_problems(files, recorded, unreadable)
        if problems:
            said = "; ".join(problems[:3]) + (
                f"; and {len(problems) - 3} more" if len(problems) > 3 else ""
            )
            raise TableLakeError(
                f"{self.root}: the table does not hold what its runs recorded, so an answer from "
                f"it would be wrong: {said}. A commit file of the table's log "
                f"({self.uri}/_delta_log) was edited or deleted; `objsearch lake verify "
                f"{self.root}` names the runs. Nothing was read or changed"
            )
        return unreadable

    def _log_problems(self, table: Any, *, writing: bool = True) -> list[str]:
        """What is wrong with the table's log that delta-rs reads past: a version older than
        one this lake recorded committing (:data:`HEAD_FILE`: the newest commit files were
        deleted, and the runs they committed with them), and — ``writing`` — the latest
        version's commit file missing (read from its checkpoint, the table cannot take a
        commit: delta-rs fails it with "Invalid table version")."""
        problems = []
        version = int(table.version())
        head = self._recorded_head()
        if head is not None and head > version:
            # The table handed in may only be older than a commit another writer made since it
            # was loaded (the head record is written after that commit): damage only if the log
            # as it is now still ends before the recorded head.
            version = max(version, int(self.table().version()))
        if head is not None and head > version:
            problems.append(
                f"the log ends at version {version}, but a commit of version {head} was made "
                f"({HEAD_FILE} records it): the commit file(s) of version {version + 1} to "
                f"{head} are missing, with every row they committed"
            )
        if writing and not self.remote:
            latest = Path(self.uri) / "_delta_log" / f"{version:020d}.json"
            if not latest.exists():
                problems.append(
                    f"the commit file of the latest version, _delta_log/{latest.name}, is "
                    "missing (the version reads from its checkpoint, but no commit can follow "
                    "it): restore the file"
                )
        return problems

    def _empty_commits(self) -> list[str]:
        """Commit files of the log (local) after its latest checkpoint — those a reader reads
        — that hold no action but their ``commitInfo``: every commit this lake makes adds,
        removes or records something, so one cut down to its first line took a whole commit
        out (a run with its record, which no count can see). A checkpoint comes with each
        compaction, so these are the commits since the last one (a ``lake add`` compacts past
        :data:`COMPACT_AT_FILES` files)."""
        if self.remote:
            return []
        log = Path(self.uri) / "_delta_log"
        since = -1
        with suppress(OSError, ValueError, TypeError, KeyError):
            since = int(json.loads((log / "_last_checkpoint").read_text())["version"])
        problems = []
        for path in sorted(log.glob("[0-9]*[0-9].json")):
            if not path.stem.isdigit() or int(path.stem) <= since:
                continue
            try:
                lines = path.read_text(encoding="utf-8").splitlines()
            except (OSError, UnicodeDecodeError) as exc:
                problems.append(f"commit file {path.name} cannot be read: {exc}")
                continue
            if _writes(lines) and not any(
                line.strip() and not line.startswith('{"commitInfo"') for line in lines
            ):
                problems.append(
                    f"commit file {path.name} holds no action, only its commitInfo: what it "
                    "committed (a run, with its record) is not in the table"
                )
        return problems

    def check_writable(self, table: Any) -> None:
        """Raise :class:`TableLakeError` if the table's log cannot take a commit
        (:meth:`_log_problems`)."""
        problems = self._log_problems(table)
        if problems:
            raise TableLakeError(f"{self.root}: the table's log is damaged: {'; '.join(problems)}")

    def _transaction_problems(self, table: Any, runs: Sequence[TableRun]) -> list[tuple[str, str]]:
        """Runs whose application transactions (what a writer asks instead of reading the
        ``_run`` rows) are missing from the table's log: adding their log again would count
        it twice."""
        indexed = table.transaction_version(IDENTITY_INDEX_APP) is not None
        problems = []
        for r in runs:
            apps = [_app_id(r.robot, r.run)]
            if indexed:
                apps += [_identity_app(k, v) for k, v in sorted(r.identity.items()) if v]
            missing = [a for a in apps if table.transaction_version(a) is None]
            if missing and not r.run.startswith("_"):
                problems.append(
                    (
                        r.label,
                        f"its application transaction(s) {', '.join(missing)} are missing from "
                        "the table's log (a commit file was edited): adding its log again would "
                        "not be refused, and would count its events twice",
                    )
                )
        return problems

    def _recorded_head(self) -> int | None:
        """The latest version a commit of this lake recorded making (:data:`HEAD_FILE`), or
        None (no such record, or one that does not check: then nothing is compared)."""
        try:
            if self.remote:
                fs, base = _filesystem(self.uri)
                with fs.open_input_file(f"{base}/{HEAD_FILE}") as fh:
                    text = fh.read(4096).decode()
            else:
                text = (Path(self.uri) / HEAD_FILE).read_text(encoding="utf-8")
            doc = json.loads(text)
            version = doc["version"]
            if type(version) is int and doc.get("check") == _head_check(version):
                return version
        except FileNotFoundError:
            return None
        except (OSError, ValueError, TypeError, KeyError, UnicodeDecodeError):
            pass
        _log.warning(
            "%s: %s does not check; ignored (a deleted newest commit file would go unseen until "
            "the next commit rewrites it)",
            self.root,
            HEAD_FILE,
        )
        return None

    def _record_head(self, version: int) -> None:
        """Record that the table reached ``version`` (after a commit; :data:`HEAD_FILE`),
        replaced atomically. Not a durable step: a record lost in a crash, or lowered by a
        slower writer, is older than the log, which costs only the check of newer commits."""
        text = json.dumps(
            {"format": HEAD_FORMAT, "version": version, "check": _head_check(version)}
        )
        try:
            if self.remote:
                fs, base = _filesystem(self.uri)
                with fs.open_output_stream(f"{base}/{HEAD_FILE}") as out:
                    out.write(text.encode())
                return
            tmp = Path(self.uri) / f".{HEAD_FILE}.{os.getpid()}.{uuid.uuid4().hex}.tmp"
            try:
                tmp.write_text(text, encoding="utf-8")
                os.replace(tmp, Path(self.uri) / HEAD_FILE)
            finally:
                tmp.unlink(missing_ok=True)
        except OSError as exc:
            _log.warning("%s: %s not written (%s); the commit stands", self.root, HEAD_FILE, exc)

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
            self._record_head(int(table.version()) + 1)
            return info
        try:
            self._overwrite_runs(table, robot, sorted({*replacing, run}), parts, info.commit, txns)
        except CommitFailedError as exc:
            landed = self.find(robot, run)
            if landed is not None and landed.commit == info.commit:
                return landed
            raise TableRaceLost(f"{self.root}: run {robot}/{run} changed: {exc}") from exc
        _fs.durable_step()
        self._record_head(int(table.version()) + 1)
        return info

    def record_bag(
        self, bag_id: str, robot: str | None, doc: str, stamps: Sequence[str] = ()
    ) -> None:
        """Keep a bag's ingest record that belongs to no run's commit (a bag that made no run,
        one whose events the lake held already): one row of type :data:`BAG_TYPE`, appended
        in a transaction of its own (with ``stamps`` as :meth:`commit_as_read` sets them).
        The latest row of a bag id is its record."""
        from deltalake import CommitProperties, Transaction
        from deltalake.exceptions import CommitFailedError

        self.create()
        info = TableRun(
            robot=robot or "",
            date="1970-01-01",
            run=f"_bag:{bag_id}",  # no run is named so (a run name starts with a letter)
            commit=_token(),
            rows={},
            digest="",
            source=f"bag:{bag_id}",
            identity={"bag_id": bag_id},
            attachments={"record": doc},
        )
        column, row = _small_tables({}, info, self.store)[RUN_TYPE]
        part = _widen(BAG_TYPE, row, column, info, self.store)
        adds = self._write_files({BAG_TYPE: [part]}, info.commit)
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
                self._record_head(int(table.version()) + 1)
                return
            except CommitFailedError:
                time.sleep(min(0.5, 0.01 * (attempt + 1)))
        self._delete_files(adds)
        raise TableLakeError(f"{self.root}: recording bag {bag_id[:16]} lost {COMMIT_TRIES} races")

    def bag_records(self, table: Any | None = None) -> dict[str, str]:
        """Bag id → its latest :meth:`record_bag` record."""
        table = self.table() if table is None else table
        rows = self._dataset(table, [BAG_TYPE]).to_table(columns=["commit", RUN_COLUMN]).to_pylist()
        found: dict[str, tuple[str, str]] = {}
        for row in rows:
            info = row[RUN_COLUMN]
            bag_id = json.loads(info["identity"])["bag_id"]
            doc = json.loads(info["attachments"])["record"]
            if bag_id not in found or found[bag_id][0] < row["commit"]:
                found[bag_id] = (row["commit"], doc)
        return {k: v for k, (_, v) in sorted(found.items())}

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
            self._record_head(int(table.version()) + 1)
            self._maybe_compact(table)
            return info
        if adds is not None:
            self._delete_files(adds)
        raise TableLakeError(
            f"{self.root}: the commit of run {info.run!r} lost {COMMIT_TRIES} races with other "
            "writers; try again"
        )

    def _open(self, rel: str) -> Any:
        """An output stream for a new data file (its folder made)."""
        if self.remote:
            fs, base = _filesystem(self.uri)
            return fs.open_output_stream(f"{base}/{rel}")
        path = Path(self.uri) / rel
        _fs.make_dirs(path.parent)
        return pa.OSFile(str(path), "wb")

    def _close(self, rel: str, out: Any) -> int:
        """Close a data file's stream (fsync'ed when local); its size."""
        size = int(out.tell())
        out.close()
        if self.remote:
            _fs.durable_step()  # the object is stored once its upload returns
        else:
            _fs.fsync_file(Path(self.uri) / rel)
        return size

    def _rename(self, rel: str, new: str) -> None:
        """Give a written data file its content-addressed name, durably, before a commit names
        it: locally a rename and an fsync of the folder; on S3 a copy and a delete
        (``S3FileSystem.move``), stored once it returns. (Arrow then puts an empty marker
        object ``type=<kind>/`` for the partition's "folder", as S3 consoles do: one key a
        partition, which no Delta reader reads and vacuum leaves.)"""
        if self.remote:
            fs, base = _filesystem(self.uri)
            fs.move(f"{base}/{rel}", f"{base}/{new}")
            _fs.durable_step()
            return
        table = Path(self.uri)
        _fs.rename(table / rel, table / new)
        _fs.fsync_dir((table / new).parent, step=False)

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
            self._abandon(files.values())
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
            self._abandon(written)
            self._delete_files(adds)
            raise
        return info, adds

    def _abandon(self, files: Iterable[_StreamFile]) -> None:
        """Close and delete files a failed commit was writing."""
        files = list(files)
        for f in files:
            with suppress(Exception):
                f.writer.close()
            if f.out is not None:
                with suppress(Exception):
                    self._close(f.rel, f.out)
        self._delete_files([_Named(f.rel) for f in files if f.on_storage])

    def _derive(self, files: Mapping[str, str]) -> dict[str, pa.Table]:
        """The derived tables of one run from its data files just written (``files``: event
        type → path in the table), read back a batch at a time in bounded memory: DuckDB gets
        :data:`DERIVE_MEMORY` and spills to a private temp folder beyond it; an operator that
        cannot spill and needs more gets twice as much, and so on."""
        import duckdb

        from .derived import derive_views
        from .sql_limits import progress_bar_off

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
                    self._record_head(int(table.version()) + 1)
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

    def _write_files(self, parts: Mapping[str, Sequence[pa.Table]], token: str) -> list[Any]:
        """Write each ``type``'s rows (runs in the order given, each by seq) as one Parquet
        file (zstd, page checksums) where the table keeps that partition, not yet part of the
        table: the commit that names them makes them so (vacuum removes them if none does)."""
        from deltalake.transaction import AddAction

        adds = []
        for kind in sorted(parts):
            part = pa.concat_tables(parts[kind]).drop_columns(["type"])
            sink = pa.BufferOutputStream()
            pq.write_table(
                part,
                sink,
                compression="zstd",
                row_group_size=ROW_GROUP_ROWS,
                write_page_checksum=True,
            )
            data = sink.getvalue()
            rel = _hashed_name(kind, token, hashlib.sha256(memoryview(data)).hexdigest())
            self._put(rel, data)
            stats = _stats(part)
            adds.append(
                AddAction(rel, data.size, {"type": kind}, int(time.time() * 1000), True, stats)
            )
        return adds

    def _put(self, rel: str, data: pa.Buffer) -> None:
        """Store a new data file whole, durably (contents and name), before a commit names it."""
        if self.remote:
            fs, base = _filesystem(self.uri)
            with fs.open_output_stream(f"{base}/{rel}") as out:
                out.write(data)
            _fs.durable_step()
            return
        path = Path(self.uri) / rel
        _fs.make_dirs(path.parent)
        with path.open("wb") as fh:
            fh.write(memoryview(data))
        _fs.fsync_file(path)
        _fs.fsync_dir(path.parent, step=False)  # its name too, before a commit names it

    def _delete_files(self, adds: Sequence[Any]) -> None:
        for add in adds:
            with suppress(OSError):
                if self.remote:
                    fs, base = _filesystem(self.uri)
                    fs.delete_file(f"{base}/{add.path}")
                else:
                    (Path(self.uri) / add.path).unlink()

    def _overwrite_runs(
        self,
        table: Any,
        robot: str,
        runs: Sequence[str],
        parts: Mapping[str, pa.Table],
        token: str,
        apps: Sequence[Any],
    ) -> None:
        """Replace every row of ``runs`` of ``robot`` by ``parts`` (a run's rows by ``type``;
        none: take the runs out) in one transaction decided from ``table``, carrying the
        application transactions ``apps`` and :data:`REWRITE_APP`: each data file that may hold a row of them
        (by the log's statistics) is removed, and its other rows, in their order, are written
        again with the new rows of its type after them — content-addressed, as every file this
        module writes (delta-rs's overwrite and delete name their files without a hash). A
        damaged file among them is an error naming it (rewritten, its damage would get a fresh
        hash). Raises ``CommitFailedError`` if another commit came between (what it wrote
        deleted), unless this one landed (its answer lost)."""
        from deltalake import CommitProperties
        from deltalake.transaction import RemoveAction

        commit = CommitProperties(app_transactions=[*apps, _rewrite_transaction(table)])
        holding = self._files_holding(table, robot, runs)
        for f in holding:
            problem = self._input_problem(f)
            if problem is not None:
                raise TableLakeError(
                    f"{self.root}: a data file holding run {'/'.join(runs)} of robot {robot!r} "
                    f"is damaged ({problem}); rewriting it would hide the damage: `objsearch "
                    "lake verify` names the damaged files"
                )
        by_kind: dict[str, list[DataFile]] = {}
        for f in holding:
            by_kind.setdefault(f.kind, []).append(f)
        adds: list[Any] = []
        try:
            fresh = {k: [p] for k, p in parts.items() if k not in by_kind and p.num_rows}
            adds += self._write_files(fresh, token)
            for kind in sorted(by_kind):
                written = self._rewrite(
                    kind, by_kind[kind], token, drop=(robot, runs), then=parts.get(kind)
                )
                if written is not None:
                    adds.append(written)
        except BaseException:
            self._delete_files(adds)
            raise
        now = int(time.time() * 1000)
        removes = [RemoveAction(f.path, True, now, f.size, {"type": f.kind}) for f in holding]
        self._commit_actions(table, removes, adds, commit)

    def _commit_actions(
        self, table: Any, removes: Sequence[Any], adds: Sequence[Any], commit: Any
    ) -> None:
        """One transaction decided from ``table`` that removes ``removes`` and adds ``adds``
        (files this writer has just written), with the commit properties ``commit``. Raises
        ``CommitFailedError`` if another commit came between, having deleted ``adds``, unless
        this one landed (every file it adds is in the table: its answer was lost), which returns
        as a commit does."""
        from deltalake.exceptions import CommitFailedError

        try:
            table.create_write_transaction(
                [*removes, *adds],
                mode="append",
                schema=table_schema(self.store),
                partition_by=["type"],
                commit_properties=commit,
            )
        except CommitFailedError:
            landed = {f.path for f in self.data_files(self.table())}
            if adds and all(a.path in landed for a in adds):
                return  # it landed; its answer was lost
            self._delete_files(adds)
            raise
        except BaseException:
            self._delete_files(adds)
            raise

    def _files_holding(self, table: Any, robot: str, runs: Sequence[str]) -> list[DataFile]:
        """The data files of ``table`` that may hold a row of ``runs`` of ``robot``: by the
        minimum and maximum the log records of ``robot`` and ``run`` (this module records them
        whole); a file without them, or unhashed (delta-rs may cut a string's statistics), is
        taken as holding them."""
        actions = pa.table(table.get_add_actions(flatten=True))
        n = actions.num_rows

        def column(name: str) -> list[Any]:
            return actions.column(name).to_pylist() if name in actions.column_names else [None] * n

        bounds = zip(
            actions.column("path").to_pylist(),
            column("min.robot"),
            column("max.robot"),
            column("min.run"),
            column("max.run"),
            strict=True,
        )
        maybe = set()
        for path, lo_robot, hi_robot, lo_run, hi_run in bounds:
            unknown = None in (lo_robot, hi_robot, lo_run, hi_run) or not file_sha256(str(path))
            if unknown or (
                lo_robot <= robot <= hi_robot and any(lo_run <= r <= hi_run for r in runs)
            ):
                maybe.add(str(path))
        return [f for f in self.data_files(table) if f.path in maybe]

    def remove_run(self, robot: str, run: str) -> bool:
        """Take a run out of the lake (one transaction); False if it was not there."""
        from deltalake import Transaction
        from deltalake.exceptions import CommitFailedError

        app = _app_id(robot, run)
        for attempt in range(COMMIT_TRIES):
            table = self.table()
            if self.find(robot, run, table) is None:
                return False
            version = table.transaction_version(app) or 0
            try:
                self._overwrite_runs(
                    table, robot, [run], {}, _token(), [Transaction(app, version + 1)]
                )
            except CommitFailedError:
                time.sleep(min(0.5, 0.01 * (attempt + 1)))
                continue
            _fs.durable_step()
            self._record_head(int(table.version()) + 1)
            return True
        raise TableLakeError(
            f"{self.root}: removing run {run!r} lost {COMMIT_TRIES} races; try again"
        )

    def _maybe_compact(self, table: Any) -> None:
        """Compact after a commit once the table holds many files, unless another writer
        claimed a compaction less than :data:`COMPACTION_CLAIM_FRESH_S` ago (it is compacting;
        were it not, two compactions would still not both commit). The run is committed
        whatever happens here: a compaction that fails is logged, not raised."""
        table.update_incremental()
        if len(table.file_uris()) <= COMPACT_AT_FILES:
            return
        claimed = _claim_ns(table)
        if claimed is not None and time.time_ns() - claimed < COMPACTION_CLAIM_FRESH_S * 1e9:
            return
        try:
            self._compact(vacuum_hours=None, yielding=True)
        except (TableLakeError, OSError) as exc:
            _log.warning(
                "%s: compaction after the commit failed (%s); the run is committed", self, exc
            )

    def compact(self, *, vacuum_hours: float | None = 1.0) -> dict[str, int]:
        """Rewrite the small files into few large ones (per ``type``) and every unhashed file,
        all content-addressed (:meth:`_optimize`), checkpoint the log, and
        with ``vacuum_hours`` delete files no version younger than that reads (readers that
        began earlier may still need them). Safe to run from many places at once, on a folder
        or a bucket: concurrent commits are not lost (compaction changes no data; a commit
        that loses a race with it is retried), and of two compactions that overlap only one
        commits — see :meth:`_claim`."""
        return self._compact(vacuum_hours=vacuum_hours)

    def _claim(self) -> Any | None:
        """Claim a compaction: set :data:`COMPACTION_CLAIM` (a metadata change, one
        transaction) and return the table at exactly that version, or None if another
        transaction changed the metadata first.

        Why: delta-rs (1.6.6) lets two ``optimize.compact`` commits remove the same files (their
        removes carry ``dataChange = false``, and neither conflict check fires), so two
        compactions that planned from the same files both commit and every row they rewrote is
        there twice; and ``optimize`` drops the application transactions of its
        ``CommitProperties``, so a ``Transaction`` cannot keep them apart. A metadata change
        does: every transaction that read the table before it fails (``MetadataChanged``). A
        compaction that plans from its own claim's version therefore fails if another claim
        came after it, and a claim before it was made by a compaction that either failed or
        committed first (then this one plans from the compacted files)."""
        from deltalake import DeltaTable
        from deltalake.exceptions import CommitFailedError

        table = self.table()
        claim = f"{time.time_ns()}-{uuid.uuid4().hex}"
        try:
            table.alter.set_table_properties({COMPACTION_CLAIM: claim}, raise_if_not_exists=False)
        except CommitFailedError:
            return None
        _fs.durable_step()
        pinned = DeltaTable(self.uri, version=table.version(), storage_options=self.options)
        if pinned.metadata().configuration.get(COMPACTION_CLAIM) != claim:
            return None  # cannot happen: the version the claim committed is the table's now
        return pinned

    def _optimize(self, table: Any) -> None:
        """Compact ``table`` (the claimed, pinned version): per ``type`` partition, its small
        files — and every unhashed one, so compaction makes a lake content-addressed — are
        rewritten, whole files in the log's order (a run's rows keep their order), into
        content-addressed files of at most about :data:`TARGET_FILE_BYTES`, written as the
        writers write (zstd, page checksums); one transaction from ``table`` removes the inputs
        (``dataChange = false``) and adds the outputs. Not delta-rs's ``optimize.compact``: it
        names its files itself, with no hash. A commit that fails deletes what it wrote, unless
        it landed (its answer lost)."""
        from deltalake import CommitProperties
        from deltalake.transaction import RemoveAction

        by_kind: dict[str, list[DataFile]] = {}
        for f in self.data_files(table):
            by_kind.setdefault(f.kind, []).append(f)
        removes: list[Any] = []
        adds: list[Any] = []
        try:
            for kind in sorted(by_kind):
                for planned in _compaction_groups(by_kind[kind]):
                    # A damaged input is left where it is (readers keep leaving it out): its
                    # rows rewritten would be a healthy file with a new hash, the damage hidden.
                    group = [f for f in planned if not self._damaged_input(f)]
                    if not group or (len(group) == 1 and file_sha256(group[0].path)):
                        continue
                    written = self._rewrite(kind, group, _token())  # a name of its own
                    if written is not None:
                        adds.append(written)
                    now = int(time.time() * 1000)
                    removes += [
                        RemoveAction(f.path, False, now, f.size, {"type": kind}) for f in group
                    ]
        except BaseException:
            self._delete_files(adds)
            raise
        if not removes:
            return
        commit = CommitProperties(app_transactions=[_rewrite_transaction(table)])
        self._commit_actions(table, removes, adds, commit)
        _fs.durable_step()

    def _source(self, rel: str) -> tuple[str, Any]:
        """A data file's path and file system, as Arrow's readers take them."""
        if self.remote:
            fs, base = _filesystem(self.uri)
            return f"{base}/{rel}", fs
        return str(Path(self.uri) / rel), pafs.LocalFileSystem()

    def _input_problem(self, f: DataFile) -> str | None:
        """Why a file a compaction or a replace would rewrite is not the file written (another
        size than the log records; a content-addressed one whose bytes hash otherwise; an
        unhashed one without ``PAR1`` at both ends), or None. Reads the file once (on S3:
        downloads it; the rewrite reads it again)."""
        problem: str | None
        try:
            if self.remote:
                fs, base = _filesystem(self.uri)
                digest = hashlib.sha256()
                size = 0
                with fs.open_input_file(f"{base}/{f.path}") as fh:
                    while chunk := fh.read(1 << 20):
                        digest.update(chunk)
                        size += len(chunk)
                actual = digest.hexdigest()
                head_ok = True
            else:
                path = Path(self.uri) / f.path
                size = path.stat().st_size
                actual = sha256_file(path) if file_sha256(f.path) else ""
                head_ok = file_sha256(f.path) is not None or parquet_problem(path) is None
        except OSError as exc:
            problem = f"{f.path}: {exc.strerror or exc}"
        else:
            if size != f.size:
                problem = f"{f.path} has {size} bytes, the table's log records {f.size}"
            elif not head_ok:
                problem = f"{f.path} is truncated or not Parquet (no PAR1 at both ends)"
            else:
                problem = _hash_mismatch(f, actual) if file_sha256(f.path) else None
        return problem

    def _damaged_input(self, f: DataFile) -> bool:
        """Whether a file a compaction would rewrite is damaged (:meth:`_input_problem`),
        warned of, naming it."""
        problem = self._input_problem(f)
        if problem is None:
            return False
        _log.warning(
            "%s: compaction leaves a damaged data file as it is (queries leave it out): %s",
            self.root,
            problem,
        )
        return True

    def _rewrite(
        self,
        kind: str,
        files: Sequence[DataFile],
        token: str,
        *,
        drop: tuple[str, Sequence[str]] | None = None,
        then: pa.Table | None = None,
    ) -> Any | None:
        """One content-addressed file of ``kind`` holding the rows of ``files`` in their order,
        read a batch at a time, less those of ``drop`` (a robot and runs of it), then the rows
        ``then``; its add action (None if there is no row: no file). Its columns: those the
        inputs hold (a file holds its own type's columns, one delta-rs wrote may hold all), in
        the table's order."""
        held: set[str] = set()
        for f in files:
            try:
                where, fs = self._source(f.path)
                held.update(pq.read_schema(where, filesystem=fs).names)
            except (OSError, pa.ArrowException) as exc:
                raise TableLakeError(
                    f"{self.root}: compaction cannot read {f.path} ({exc}); `objsearch lake "
                    "verify` names the damaged files"
                ) from exc
        if then is not None:
            held.update(then.column_names)
        schema = pa.schema([f for f in table_schema(self.store) if f.name in held - {"type"}])
        out = _StreamFile(self, kind, kind, token, schema=schema)
        try:
            for f in files:  # one at a time: the order of the files is the order of the rows
                try:
                    for batch in self.files_dataset([f]).to_batches(
                        columns=schema.names, use_threads=False
                    ):
                        rows = pa.Table.from_batches([batch])
                        if drop is not None:
                            robot, runs = drop
                            ours = pc.and_(
                                pc.equal(rows.column("robot"), robot),
                                pc.is_in(rows.column("run"), pa.array(list(runs), pa.string())),
                            )
                            rows = rows.filter(pc.invert(pc.fill_null(ours, False)))
                        out.add(pa.Table.from_arrays(rows.columns, schema=schema))
                except (OSError, pa.ArrowException) as exc:
                    raise TableLakeError(
                        f"{self.root}: compaction cannot read {f.path} ({exc}); `objsearch lake "
                        "verify` names the damaged files"
                    ) from exc
            if then is not None and then.num_rows:
                out.add(
                    pa.Table.from_arrays(
                        [
                            then.column(f.name).cast(f.type)
                            if f.name in then.column_names
                            else pa.nulls(then.num_rows, f.type)
                            for f in schema
                        ],
                        schema=schema,
                    )
                )
            out._flush()
            if not out.rows:
                self._abandon([out])
                return None
            return out.close()
        except BaseException:
            self._abandon([out])
            raise

    def _compact(self, *, vacuum_hours: float | None, yielding: bool = False) -> dict[str, int]:
        """``yielding``: give up at the first race lost (another writer's claim came after
        this one's, so that writer is compacting): what ``lake add`` does, since writers that
        all claimed again at once would keep failing each other's compactions (4 writers
        compacting every 30 files on moto's bucket: each compaction lost 50 races)."""
        from deltalake.exceptions import CommitFailedError

        # Compaction and vacuum would make a loss permanent: the files of a removed ``add`` are
        # deleted as unreferenced, the rows of a deleted newest commit with them.
        current = self.table()
        self.check_runs(current)
        self.check_writable(current)
        before = len(current.file_uris())
        for attempt in range(COMMIT_TRIES):
            table = self._claim()
            if table is not None:
                try:
                    self._optimize(table)
                    break
                except CommitFailedError as exc:
                    _log.debug("%s: compaction lost a race (%s); again", self, exc)
            if yielding:
                return {"files_before": before, "files_after": before, "vacuumed": 0}
            time.sleep(min(0.5, 0.01 * (attempt + 1)) * (1 + random.random()))
        else:
            raise TableLakeError(
                f"{self.root}: compaction lost {COMMIT_TRIES} races with other writers; try again"
            )
        table = self.table()
        table.create_checkpoint()
        _fs.durable_step()
        self._record_head(int(table.version()))
        removed = 0
        if vacuum_hours is not None:
            removed = len(
                table.vacuum(
                    retention_hours=math.ceil(vacuum_hours),  # whole hours; never rounded down
                    enforce_retention_duration=False,
                    dry_run=False,
                    # also files no commit ever named (a writer killed before its commit);
                    # one younger than the retention may be a commit in flight: kept
                    full=True,
                )
            )
            _fs.durable_step()
            table.cleanup_metadata()
            _fs.durable_step()
        return {"files_before": before, "files_after": len(table.file_uris()), "vacuumed": removed}


#: Rows of one event type hashed at a time by :func:`ipc_digest` (the version-1 digest, kept to
#: check the runs committed with it; version 2 is :mod:`.run_digest`).
DIGEST_ROWS: Final = 1 << 16
#: DuckDB's memory for the derived tables of a streamed commit (bytes; it spills beyond), and
#: the most it is given when an operator that cannot spill needs more.
DERIVE_MEMORY: Final = 48 << 20
DERIVE_MEMORY_MAX: Final = 4 << 30
#: Events read from a log at a time by the streaming commit (a chunk of 16 Ki synthetic events
#: costs ~46 MB while it is turned into tables; benchmarks/lake_add_memory.py).
CHUNK_EVENTS: Final = 1 << 13
#: A streamed data file stays in memory until its bytes pass this, then goes on in a temporary
#: file: a smaller one is stored once, under its final name (one durable step, not three: the
#: kill tests' and a short run's cost), and the ~16 files of a long run hold at most this each.
SPILL_BYTES: Final = 1 << 20


class _HashSink:
    """A writable file whose bytes update a hash."""

    def __init__(self, digest: Any) -> None:
        self._digest = digest
        self.closed = False

    def write(self, data: Any) -> int:
        view = memoryview(data)
        self._digest.update(view)
        return view.nbytes

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self.closed = True


class _TypeDigest:
    """The version-1 digest of one type's rows: SHA-256 of slices of :data:`DIGEST_ROWS` (each
    as one Arrow IPC stream), whatever chunks they are fed in. The bytes of the buffers, not the
    values: rows read back from Parquet may not hash as they did (:mod:`.run_digest`)."""

    def __init__(self) -> None:
        self._hash = hashlib.sha256()
        self._pending: list[pa.Table] = []
        self._rows = 0

    def add(self, table: pa.Table) -> None:
        self._pending.append(table)
        self._rows += table.num_rows
        while self._rows >= DIGEST_ROWS:
            joined = pa.concat_tables(self._pending)
            self._slice(joined.slice(0, DIGEST_ROWS))
            rest = joined.slice(DIGEST_ROWS)
            self._pending, self._rows = [rest], rest.num_rows

    def _slice(self, table: pa.Table) -> None:
        # ``take`` copies the rows into fresh buffers: IPC writes a slice's whole parent
        # buffers, so the bytes would depend on how the rows were chunked, not only on them.
        compact = table.take(pa.array(range(table.num_rows), pa.int64())).combine_chunks()
        # the stream's bytes go straight into the hash (never a second copy of the slice)
        with pa.ipc.new_stream(pa.PythonFile(_HashSink(self._hash), mode="w"), table.schema) as w:
            w.write_table(compact)

    def hexdigest(self) -> str:
        if self._rows:
            self._slice(pa.concat_tables(self._pending))
            self._pending, self._rows = [], 0
        return self._hash.hexdigest()


def _combine(per_type: Mapping[str, str]) -> str:
    h = hashlib.sha256()
    for event_type in sorted(per_type):
        h.update(f"{event_type}\0{per_type[event_type]}\n".encode())
    return "sha256:" + h.hexdigest()


def table_digest(tables: Mapping[str, pa.Table]) -> str:
    """The digest of a run's event tables (conformed to their schemas, by seq): of their values
    (version 2, :mod:`.run_digest`)."""
    return values_digest(tables)


def committed_schema(event_type: str, version: int | None, store: Store) -> pa.Schema:
    """The schema :func:`event_schema` gave ``event_type`` when ``version`` was its latest (its
    latest now if None): what a version-1 digest hashed."""
    if version is None:
        return event_schema(event_type, store)
    schema = store.registry.schema(event_type, version)
    fields = payload_schema(schema, f"{event_type} v{version}")
    return pa.schema([*ENVELOPE_COLUMNS, *fields], metadata={"event_type": event_type})


def _ipc_type_digest(table: pa.Table) -> str:
    d = _TypeDigest()
    d.add(table)
    return d.hexdigest()


def ipc_digest(tables: Mapping[str, pa.Table]) -> str:
    """The version-1 digest (``sha256:…``, Arrow IPC bytes) of a run's event tables."""
    digests = {}
    for event_type, table in tables.items():
        d = _TypeDigest()
        d.add(table)
        digests[event_type] = d.hexdigest()
    return _combine(digests)


def _chunks(events: Iterable[Event], store: Store) -> Iterator[dict[str, pa.Table]]:
    """The events as conformed typed tables, :data:`CHUNK_EVENTS` events at a time."""
    batch: list[Event] = []
    for event in events:
        batch.append(event)
        if len(batch) == CHUNK_EVENTS:
            tables = events_to_tables(batch, store)
            yield {t: _conform(t, table, store) for t, table in tables.items()}
            batch = []
    if batch:
        tables = events_to_tables(batch, store)
        yield {t: _conform(t, table, store) for t, table in tables.items()}


def stream_digest(events: Iterable[Event], store: Store) -> tuple[str, dict[str, int]]:
    """The digest :func:`table_digest` gives, and the rows per type, read in chunks."""
    digest = RunDigest()
    rows: dict[str, int] = {}
    for chunk in _chunks(events, store):
        for event_type, table in chunk.items():
            digest.add(event_type, table)
            rows[event_type] = rows.get(event_type, 0) + table.num_rows
    return digest.hexdigest(), rows


class _TeeSink:
    """A writable file that passes every byte on to ``out`` and into a hash (a streamed data
    file is hashed as it is written, never read back)."""

    def __init__(self, out: Any, digest: Any) -> None:
        self._out = out
        self._digest = digest
        self._size = 0
        self.closed = False

    def retarget(self, out: Any) -> None:
        """Pass the bytes to come on to ``out`` instead."""
        self._out = out

    def write(self, data: Any) -> int:
        view = memoryview(data)
        self._out.write(view)
        self._digest.update(view)
        self._size += view.nbytes
        return view.nbytes

    def tell(self) -> int:
        return self._size

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self.closed = True  # ``out`` is closed by its owner


class _StreamFile:
    """One ``type`` partition's Parquet file, written as rows arrive (row groups of
    :data:`ROW_GROUP_ROWS`), with the statistics the Delta log keeps, hashed as it is written.
    Its bytes stay in memory until they pass :data:`SPILL_BYTES`: a file that never does (most
    of a run's types, every file of a short run) is stored once, under its content-addressed
    name (:func:`_hashed_name`), when closed. A larger one spills to a temporary name in the
    partition's folder (``part-<token>.zstd.parquet``), is written on from there, then renamed
    to its content-addressed name when closed. A file a killed writer leaves under either name
    is no file of the table (vacuum deletes it).
    ``schema``: the file's columns (default: those of ``column``'s rows, :func:`file_schema`)."""

    def __init__(
        self,
        lake: TableLake,
        kind: str,
        column: str,
        token: str,
        schema: pa.Schema | None = None,
    ) -> None:
        self.kind = kind
        self.token = token
        self.rel = f"type={kind}/part-{token}.zstd.parquet"
        self.lake = lake
        self.memory: io.BytesIO | None = io.BytesIO()
        self.out: Any = None  # the temporary file, once spilled
        #: Whether bytes of it are on storage under ``rel`` (spilled, or closed): what a failed
        #: commit deletes.
        self.on_storage = False
        self.digest = hashlib.sha256()
        self.tee = _TeeSink(self.memory, self.digest)
        self.sink = pa.PythonFile(self.tee, mode="w")
        if schema is None:
            schema = file_schema(
                column, envelope=kind in lake.store.registry.types, store=lake.store
            )
        if "type" in schema.names:
            schema = schema.remove(schema.get_field_index("type"))
        self.schema = schema
        self.writer = pq.ParquetWriter(
            self.sink, schema, compression="zstd", write_page_checksum=True
        )
        self.pending: list[pa.Table] = []
        self.buffered = 0
        self.rows = 0
        self.stats: list[str] = []

    def add(self, table: pa.Table) -> None:
        if "type" in table.column_names:
            table = table.drop_columns(["type"])
        self.pending.append(table)
        self.buffered += table.num_rows
        if self.buffered >= min(ROW_GROUP_ROWS, CHUNK_EVENTS):
            self._flush()

    def _flush(self) -> None:
        if not self.pending:
            return
        part = pa.concat_tables(self.pending)
        self.writer.write_table(part, row_group_size=ROW_GROUP_ROWS)
        self.stats.append(_stats(part))
        self.rows += part.num_rows
        self.pending, self.buffered = [], 0
        if self.memory is not None and self.memory.tell() > SPILL_BYTES:
            self._spill()

    def _spill(self) -> None:
        """Go on writing in the temporary file, the bytes so far first (hashed already)."""
        assert self.memory is not None
        self.out = self.lake._open(self.rel)
        self.out.write(self.memory.getbuffer())
        self.tee.retarget(self.out)
        self.memory = None
        self.on_storage = True

    def close(self) -> Any:
        from deltalake.transaction import AddAction

        self._flush()
        self.writer.close()
        final = _hashed_name(self.kind, self.token, self.digest.hexdigest())
        if self.memory is not None:
            data = self.memory.getbuffer()
            size = data.nbytes
            # a put that fails may leave part of it there: a failed commit deletes it too
            self.rel, self.on_storage = final, True
            self.lake._put(final, pa.py_buffer(data))
            del data
            self.memory = None
        else:
            size = self.lake._close(self.rel, self.out)
            self.out = None
            self.lake._rename(self.rel, final)
        self.rel = final
        self.on_storage = True
        return AddAction(
            self.rel, size, {"type": self.kind}, int(time.time() * 1000), True, _merge(self.stats)
        )


def _compaction_groups(files: Sequence[DataFile]) -> list[list[DataFile]]:
    """The files of one partition a compaction rewrites, each group into one file: the small
    ones (under half of :data:`TARGET_FILE_BYTES`) and every unhashed one, in the log's order,
    a group holding at most about :data:`TARGET_FILE_BYTES`; a group of one content-addressed
    file is left as it is."""
    groups: list[list[DataFile]] = []
    group: list[DataFile] = []
    size = 0
    for f in files:
        if f.size >= TARGET_FILE_BYTES // 2 and file_sha256(f.path) is not None:
            continue
        if group and size + f.size > TARGET_FILE_BYTES:
            groups.append(group)
            group, size = [], 0
        group.append(f)
        size += f.size
    if group:
        groups.append(group)
    return [g for g in groups if len(g) > 1 or file_sha256(g[0].path) is None]


def _merge(stats: Sequence[str]) -> str:
    """The statistics of a file written in parts (min of mins, max of maxes, sums)."""
    docs = [json.loads(s) for s in stats]
    low: dict[str, Any] = {}
    high: dict[str, Any] = {}
    nulls: dict[str, int] = {}
    for doc in docs:
        for k, v in doc["minValues"].items():
            low[k] = v if k not in low else min(low[k], v)
        for k, v in doc["maxValues"].items():
            high[k] = v if k not in high else max(high[k], v)
        for k, v in doc["nullCount"].items():
            nulls[k] = nulls.get(k, 0) + v
    rows = sum(d["numRecords"] for d in docs)
    return json.dumps({"numRecords": rows, "minValues": low, "maxValues": high, "nullCount": nulls})


def _filesystem(uri: str) -> tuple[Any, str]:
    """Arrow's file system for a remote table URI and the path in it (S3: the standard AWS_*
    variables, ``AWS_ENDPOINT_URL`` included); one per URI and settings (making one costs a
    round of the SDK's credential lookup)."""
    keys = ("AWS_ENDPOINT_URL", "AWS_REGION", "AWS_DEFAULT_REGION", "AWS_ACCESS_KEY_ID")
    return _filesystem_for(uri, tuple(os.environ.get(k, "") for k in keys))


@functools.cache
def _filesystem_for(uri: str, settings: tuple[str, ...]) -> tuple[Any, str]:
    import pyarrow.fs as pafs

    endpoint = settings[0] or None
    if uri.startswith("s3://"):
        fs = pafs.S3FileSystem(
            endpoint_override=endpoint,
            scheme="http" if endpoint and endpoint.startswith("http://") else "https",
            region=os.environ.get("AWS_REGION", os.environ.get("AWS_DEFAULT_REGION", "us-east-1")),
            # The SDK's defaults (3 s without a byte, 3 attempts) fail a writer whose server
            # stalls for seconds — a loaded one does (the S3 writers' test failed so once).
            request_timeout=S3_REQUEST_TIMEOUT_S,
            connect_timeout=S3_CONNECT_TIMEOUT_S,
            retry_strategy=pafs.AwsStandardS3RetryStrategy(max_attempts=S3_ATTEMPTS),
        )
        return fs, uri.removeprefix("s3://")
    fs, path = pafs.FileSystem.from_uri(uri)
    return fs, path


def _stats(part: pa.Table) -> str:
    """A data file's statistics as the Delta log keeps them: rows, and min / max of the run
    columns and of ``seq`` and ``time_ns`` (file pruning by robot, run or time)."""
    low: dict[str, Any] = {}
    high: dict[str, Any] = {}
    nulls: dict[str, int] = {}
    for name in ("robot", "date", "run", "commit", "seq", "time_ns"):
        if name not in part.column_names:
            continue
        column = part.column(name)
        nulls[name] = column.null_count
        if column.null_count == len(column):
            continue
        bounds = pc.min_max(column)
        lo, hi = bounds["min"].as_py(), bounds["max"].as_py()
        low[name] = lo.isoformat() if isinstance(lo, dt.date) else lo
        high[name] = hi.isoformat() if isinstance(hi, dt.date) else hi
    return json.dumps(
        {"numRecords": part.num_rows, "minValues": low, "maxValues": high, "nullCount": nulls}
    )


def file_sha256(path: str) -> str | None:
    """The SHA-256 a data file's name records (hex), or None for an unhashed file."""
    found = _HASHED_NAME.search(path.rpartition("/")[2])
    return found.group(1) if found else None


def _hash_mismatch(f: DataFile, actual: str) -> str | None:
    """Why a data file whose bytes hash to ``actual`` is not the file written, or None."""
    expected = file_sha256(f.path)
    if expected is None or actual == expected:
        return None
    return (
        f"{f.path}: its bytes are not the ones written (SHA-256 {actual[:16]}…, its name "
        f"records {expected[:16]}…): changed after the commit"
    )


def _hashed_name(kind: str, token: str, sha256: str) -> str:
    return f"type={kind}/part-{token}-{sha256}.zstd.parquet"


def _token() -> str:
    return f"{time.time_ns():x}-{uuid.uuid4().hex}"


def _claim_ns(table: Any) -> int | None:
    """When the table's latest compaction claim was made (ns since the epoch), if any."""
    claim = str(table.metadata().configuration.get(COMPACTION_CLAIM) or "")
    head = claim.partition("-")[0]
    return int(head) if head.isdigit() else None


def _app_id(robot: str, run: str) -> str:
    return f"objsearch/{robot}/{run}"


#: Set when the table is made: every commit of this table records its run's identity values as
#: application transactions (:func:`_identity_app`), so :meth:`TableLake.holding` answers "no
#: run holds these" from the log alone. A table made before has no such marker: it reads the
#: ``_run`` rows every time.
IDENTITY_INDEX_APP: Final = "objsearch/identity-index"
#: Set when the table is made: the commits of this table stamp what they record with
#: application transactions (``stamps`` of :meth:`TableLake.commit_as_read` and
#: :meth:`TableLake.record_bag`; ingest stamps each bag piece), so "is this bag here?" is
#: answered from the log alone. A table made before has no such marker: ingest reads its rows.
STAMP_INDEX_APP: Final = "objsearch/stamp-index"


#: Carried by every transaction that removes data files and writes their rows again (a
#: compaction, a replace, a removal), each at the version after the one its table read: of two
#: that overlap, the second fails and reads again. delta-rs (1.6.6) does not fail an append
#: whose remove actions name files another commit removed since (the rows they held, rewritten
#: by both, would be there twice: a replace that read the table between a compaction's claim
#: and its commit did so); a shared application transaction does.
REWRITE_APP: Final = "objsearch/rewrite"


def _rewrite_transaction(table: Any) -> Any:
    from deltalake import Transaction

    return Transaction(REWRITE_APP, (table.transaction_version(REWRITE_APP) or 0) + 1)


def _identity_app(key: str, value: str) -> str:
    return f"objsearch/identity/{key}={value}"


def _transactions(table: Any, info: TableRun) -> list[Any]:
    """The application transactions a commit of ``info`` carries: its run's (two writers of
    one run conflict on it) and one per identity value (the same for one recording)."""
    from deltalake import Transaction

    apps = [_app_id(info.robot, info.run)]
    apps += [_identity_app(k, v) for k, v in sorted(info.identity.items()) if v]
    return [Transaction(a, (table.transaction_version(a) or 0) + 1) for a in apps]


def stamp_version(table: Any) -> int:
    """The version a commit decided from ``table`` stamps with: past every version a commit
    decided from an earlier table stamped with (two commits decided from one table that stamp
    the same thing carry the same application transaction: one of them fails)."""
    return int(table.version()) + 1


#: What a ``_run`` row that is no run's record raises when read (:func:`_run_of`).
_RECORD_ERRORS: Final = (TypeError, ValueError, KeyError, AttributeError)
#: Where a commit records the latest version it made (in the table's folder; Delta readers and
#: vacuum leave a name starting with ``_`` alone): a version of the table older than this means
#: its newest commit files were deleted (:meth:`TableLake.check_runs`).
HEAD_FILE: Final = "_objsearch_head.json"
HEAD_FORMAT: Final = "objsearch.head/1"
#: A ``rows`` key of a ``_run`` row that names a derived table's partition, not an event type.
_DERIVED_PREFIX: Final = "derived."


def _writes(lines: Sequence[str]) -> bool:
    """Whether a commit file's ``commitInfo`` says it is a write (every commit of this module
    that adds, removes or records: ``create_write_transaction``), not a commit that holds no
    action by design (delta-rs's ``VACUUM START`` / ``VACUUM END``)."""
    for line in lines:
        if line.startswith('{"commitInfo"'):
            with suppress(ValueError, TypeError, KeyError, AttributeError):
                return bool(json.loads(line)["commitInfo"].get("operation") == "WRITE")
            return False
    return False


def _head_check(version: int) -> str:
    return hashlib.sha256(f"{HEAD_FORMAT}:{version}".encode()).hexdigest()[:16]


def _unreadable_records(
    root: Path | str,
    unreadable: Sequence[tuple[DataFile, str]],
    what: str = "the records of its runs cannot be read",
) -> TableLakeError:
    return TableLakeError(
        f"{root}: {what}: "
        + "; ".join(why for _, why in unreadable)
        + f" (a damaged `_run` file; `objsearch lake verify {root}` lists every damaged file)"
    )


def _tally(records: pa.Table, store: Store) -> tuple[dict[str, int], list[str]]:
    """What ``_run`` rows (``robot``, ``run`` and their ``rows`` JSON) add up to per
    partition (derived partitions only when every run records them), each distinct ``rows``
    parsed once; and the runs recorded more than once (``robot/run``). Raises ValueError or
    TypeError for a ``rows`` that is no record's."""
    recorded: dict[str, int] = {t: 0 for t in store.registry.types}
    recorded[RUN_TYPE] = records.num_rows
    docs = []
    for item in pc.value_counts(records.column("rows").combine_chunks()).to_pylist():
        doc = json.loads(item["values"])
        if not isinstance(doc, dict) or not all(type(n) is int for n in doc.values()):
            raise ValueError(f"rows {item['values']!r}")
        docs.append((doc, int(item["counts"])))
    every = all(any(k.startswith(_DERIVED_PREFIX) for k in doc) for doc, _ in docs)
    for doc, count in docs:
        for kind, n in doc.items():
            if every or not kind.startswith(_DERIVED_PREFIX):
                recorded[kind] = recorded.get(kind, 0) + n * count
    per_run = records.group_by(["robot", "run"]).aggregate([([], "count_all")])
    twice = [
        f"{robot}/{run}"
        for robot, run, n in zip(*per_run.to_pydict().values(), strict=True)
        if n > 1
    ]
    return recorded, sorted(twice)


def _count_problems(
    files: Sequence[DataFile],
    recorded: Mapping[str, int],
    unreadable: Sequence[tuple[DataFile, str]],
) -> list[str]:
    """Partitions whose rows, by the table's log, are not what the runs' records add up to
    (with ``_run`` files that cannot be read: only fewer rows than the readable records name
    is wrong, and their own rows count as recorded)."""
    held: dict[str, int] = {}
    unknown: set[str] = set()
    for f in files:
        if f.rows is None:
            unknown.add(f.kind)
        else:
            held[f.kind] = held.get(f.kind, 0) + f.rows
    recorded = {**recorded, RUN_TYPE: recorded[RUN_TYPE] + sum(f.rows or 0 for f, _ in unreadable)}
    problems = []
    for kind in sorted(recorded):
        got, want = held.get(kind, 0), recorded[kind]
        if kind in unknown or got == want or (unreadable and got > want):
            continue
        if got < want:
            why = f"{want - got} row(s) the runs recorded are in no data file of the log"
        else:
            why = f"{got - want} row(s) no run's record names"
        problems.append(f"type={kind} holds {got} rows, the runs recorded {want} ({why})")
    return problems


def _run_problems(
    runs: Sequence[TableRun],
    held: Mapping[tuple[str, str, str, str], int],
    damaged_kinds: set[str],
    unreadable: bool,
) -> list[tuple[str, str]]:
    """Each run whose rows of a type in the table (``held``: by robot, run, commit, type) are
    not what its ``_run`` row records, and rows of a commit no ``_run`` row records (not with
    ``unreadable`` records: they may be those runs'). A type with a damaged file is left to
    that file's report."""
    problems = []
    commits = {(r.robot, r.run, r.commit) for r in runs}
    for r in runs:
        want = {**r.rows, **r.derived_rows, RUN_TYPE: 1}
        for kind in sorted(want):
            got = held.get((r.robot, r.run, r.commit, kind), 0)
            if got != want[kind] and kind not in damaged_kinds:
                problems.append(
                    (
                        r.label,
                        f"type={kind}: {got} row(s) in the table, its `_run` row records "
                        f"{want[kind]} (a data file's `add` is missing from the table's log)",
                    )
                )
    if not unreadable:
        kinds_recorded = {k for r in runs for k in (*r.rows, *r.derived_rows, RUN_TYPE)}
        unrecorded: dict[tuple[str, str, str], dict[str, int]] = {}
        for (robot, run, commit, kind), n in sorted(held.items()):
            if (robot, run, commit) in commits or kind in damaged_kinds:
                continue
            if kind in kinds_recorded or not kind.startswith((_DERIVED_PREFIX, "_")):
                unrecorded.setdefault((robot, run, commit), {})[kind] = n
        for (robot, run, commit), kinds in unrecorded.items():
            problems.append(
                (
                    f"{robot}/{run}",
                    f"{sum(kinds.values())} row(s) of {len(kinds)} type(s) "
                    f"({', '.join(sorted(kinds))}) of commit {commit[:16]}… that no `_run` row "
                    "records (its `_run` file's `add` is missing from the table's log)",
                )
            )
    return problems


def _run_of(row: Mapping[str, Any]) -> TableRun:
    info = row[RUN_COLUMN]
    rows = json.loads(info["rows"])
    if not isinstance(rows, dict) or not all(type(n) is int for n in rows.values()):
        raise ValueError(f"rows {info['rows']!r}")
    return TableRun(
        robot=row["robot"],
        date=row["date"].isoformat(),
        run=row["run"],
        commit=row["commit"],
        rows={t: n for t, n in rows.items() if not t.startswith(_DERIVED_PREFIX)},
        derived_rows={t: n for t, n in rows.items() if t.startswith(_DERIVED_PREFIX)},
        digest=info["digest"],
        source=info["source"],
        identity=json.loads(info["identity"]),
        attachments=json.loads(info["attachments"]),
    )


def run_rows(tables: Mapping[str, pa.Table], info: TableRun, store: Store) -> pa.Table:
    """A run's rows in the fleet table, as one table (see :func:`run_parts`)."""
    return pa.concat_tables(run_parts(tables, info, store).values(), promote_options="default")


def run_parts(tables: Mapping[str, pa.Table], info: TableRun, store: Store) -> dict[str, pa.Table]:
    """A run's rows in the fleet table by ``type`` partition: its events (by seq), its derived
    tables and its ``_run`` row."""
    derived = derive_run(tables, robot=info.robot, date=info.date, run=info.run, store=store)
    parts = {
        t: _widen(t, table.sort_by("seq"), t, info, store) for t, table in sorted(tables.items())
    }
    return parts | _small_parts(derived, info, store)


def _small_parts(
    derived: Mapping[str, pa.Table], info: TableRun, store: Store
) -> dict[str, pa.Table]:
    """A run's derived tables and its ``_run`` row, by ``type`` partition."""
    return {
        kind: _widen(kind, table, column, info, store)
        for kind, (column, table) in _small_tables(derived, info, store).items()
    }


def _small_tables(
    derived: Mapping[str, pa.Table], info: TableRun, store: Store
) -> dict[str, tuple[str, pa.Table]]:
    """A run's derived tables and its ``_run`` row, by ``type`` partition: the struct column
    each goes in and its rows, before :func:`_widen`."""
    parts = {}
    specs = {d.name: d for d in derived_tables(store)}
    for name, table in derived.items():
        parts[derived_kind(name, specs[name].version)] = (derived_column(name), table)
    # The rows of each derived partition beside the events' (read back as ``derived_rows``),
    # so the table's rows of every partition can be counted against the runs' records.
    rows = {**info.rows, **{kind: table.num_rows for kind, (_, table) in parts.items()}}
    description = {
        "format": TABLE_FORMAT,
        "digest": info.digest,
        "rows": json.dumps(rows, sort_keys=True),
        "source": info.source,
        "identity": json.dumps(dict(info.identity), sort_keys=True),
        "attachments": json.dumps(dict(info.attachments), sort_keys=True),
        "committed_at_ns": time.time_ns(),
    }
    parts[RUN_TYPE] = (RUN_COLUMN, pa.table({k: [v] for k, v in description.items()}))
    return parts


class _Named(NamedTuple):
    path: str


def _widen(kind: str, table: pa.Table, column: str, info: TableRun, store: Store) -> pa.Table:
    """``table`` as rows of the fleet table: the run's columns, its envelope (if it has one)
    and its other columns as the struct ``column``. The other types' columns are left out of
    the file (every Delta reader reads a column a file lacks as null; a file of nulls for
    twenty-odd structs would cost more memory than the rows themselves)."""
    schema = file_schema(column, envelope=kind in store.registry.types, store=store)
    n = table.num_rows
    envelope = {f.name for f in ENVELOPE_COLUMNS}
    base = {
        "robot": pa.array([info.robot] * n, pa.string()),
        "date": pa.array([dt.date.fromisoformat(info.date)] * n, pa.date32()),
        "run": pa.array([info.run] * n, pa.string()),
        "commit": pa.array([info.commit] * n, pa.string()),
        "type": pa.array([kind] * n, pa.string()),
    }
    arrays = []
    for field in schema:
        if field.name in base:
            arrays.append(base[field.name])
        elif field.name in envelope:
            arrays.append(
                table.column(field.name).combine_chunks().cast(field.type)
                if field.name in table.column_names
                else pa.nulls(n, field.type)
            )
        elif field.name == column:
            parts = [
                (
                    table.column(f.name).combine_chunks()
                    if f.name in table.column_names
                    else pa.nulls(n, f.type)
                ).cast(f.type)
                for f in field.type
                if f.name not in PARTITION_NAMES
            ]
            names = [f for f in field.type if f.name not in PARTITION_NAMES]
            arrays.append(
                pa.StructArray.from_arrays(parts, fields=names) if n else pa.array([], field.type)
            )
    return pa.Table.from_arrays(arrays, schema=schema)


@functools.cache
def file_schema(column: str, *, envelope: bool, store: Store) -> pa.Schema:
    """The columns a data file of one ``type`` holds: the run's, the envelope (event types),
    and its own struct ``column`` — in the table schema's order."""
    names = {f.name for f in BASE_COLUMNS} | {column}
    if envelope:
        names |= {f.name for f in ENVELOPE_COLUMNS}
    return pa.schema([f for f in table_schema(store) if f.name in names])


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


__all__ = [
    "TABLE_FORMAT",
    "EventStoreError",
    "TableLake",
    "TableLakeError",
    "TableRun",
    "add_log",
    "is_table_lake",
    "run_parts",
    "run_rows",
    "table_schema",
]
