"""The fleet lake's table: its columns (the run's, the envelope, one struct per event type and
derived table, a ``_run`` row's description), what a run's rows look like in it, and the records
its readers and writers share (:class:`TableRun`, :class:`DataFile`, :class:`TableCheck`)."""

from __future__ import annotations

import dataclasses
import datetime as dt
import functools
import json
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

import pyarrow as pa

from ..arrow import ENVELOPE_COLUMNS, event_schema
from ..derived import PARTITION_NAMES, derive_run, derived_tables
from ..store import Store
from .common import LakeError

TABLE_FORMAT: Final = "objsearch.lake/2"
TABLE_DIR: Final = "events"
RUN_TYPE: Final = "_run"
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
    if all(k in store.registry.types or k.startswith("_") for k in kinds):
        return _events_schema(store)
    return table_schema(store)


#: What a ``_run`` row that is no run's record raises when read (:func:`_run_of`).
_RECORD_ERRORS: Final = (TypeError, ValueError, KeyError, AttributeError)
#: A ``rows`` key of a ``_run`` row that names a derived table's partition, not an event type.
_DERIVED_PREFIX: Final = "derived."


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
