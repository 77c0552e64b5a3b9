"""DuckDB over the lake: one view per event type, and ``events`` with every event's envelope.

Views read the fleet lake's data files in place (nothing is copied into DuckDB) with the run's
columns ``robot`` (VARCHAR), ``date`` (DATE) and ``run`` (VARCHAR). A type without any file in
the lake still gets its view, empty but with its typed columns, so queries never depend on which
event types happen to have occurred. Views read the files the table lists, damaged ones left out
(:func:`create_fleet_views`).

:func:`lock_down` makes a connection the analysts' sandbox: it reads the lake's folder and
nothing else, writes no file, loads no extension, and cannot change that (DuckDB's own settings);
:func:`check_read_only` refuses every statement but ``SELECT`` (and ``EXPLAIN`` of one), which
also keeps ``COPY … TO`` from writing into the lake folder it may read.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Final

import duckdb
import pyarrow as pa

from .arrow import ENVELOPE_COLUMNS, event_schema
from .errors import EventStoreError
from .lake import DataFile, TableLake
from .sql_quote import quote_ident, quote_literal

PARTITION_COLUMNS: Final = (("robot", "VARCHAR"), ("date", "DATE"), ("run", "VARCHAR"))
_EXPLAIN: Final = re.compile(r"\s*EXPLAIN\s+(?:ANALY[SZ]E\s+)?", re.IGNORECASE)


class QueryRefusedError(EventStoreError):
    """A query would do more than read the lake (write, attach, configure, load, …)."""


# ``time``: the run's one clock (time_ns) as a real TIMESTAMP (UTC, microseconds). A bag run is on
# the bag's clock (epoch); a simulated log's clock starts at 0, i.e. 1970-01-01.
_TIME = "make_timestamp(time_ns // 1000) AS time"


def lock_down(con: duckdb.DuckDBPyConnection, readable: Sequence[Path]) -> None:
    """Let the connection read files under ``readable`` folders and nothing else, load no
    extension, and lock its configuration so no later statement can undo it."""
    folders = sorted(
        {str(p.absolute()) + "/" for p in readable} | {str(p.resolve()) + "/" for p in readable}
    )
    con.execute("SET allowed_directories = [" + ", ".join(quote_literal(f) for f in folders) + "]")
    for setting in (
        "enable_external_access = false",
        "autoinstall_known_extensions = false",
        "autoload_known_extensions = false",
        "allow_community_extensions = false",
        "lock_configuration = true",
    ):
        con.execute(f"SET {setting}")


def check_read_only(con: duckdb.DuckDBPyConnection, sql: str) -> None:
    """Raise :class:`QueryRefusedError` unless ``sql`` is one or more ``SELECT`` statements
    (``EXPLAIN`` of one included). Syntax errors raise DuckDB's own ``ParserException``."""
    statements = con.extract_statements(sql)
    if not statements:
        raise QueryRefusedError("no SQL statement given")
    for statement in statements:
        if statement.type == duckdb.StatementType.SELECT:
            continue
        if statement.type == duckdb.StatementType.EXPLAIN:
            explained = _EXPLAIN.match(statement.query)
            if explained is not None:
                inner = con.extract_statements(statement.query[explained.end() :])
                if [s.type for s in inner] == [duckdb.StatementType.SELECT]:
                    continue
        text = " ".join(statement.query.split())
        raise QueryRefusedError(
            f"queries over the lake are read-only: only SELECT runs, not {statement.type.name} "
            f"({text[:60]}{'…' if len(text) > 60 else ''}); to write a result file, use --out "
            "PATH; a PIVOT runs as SELECT * FROM (PIVOT …)"
        )


def create_fleet_views(
    con: duckdb.DuckDBPyConnection,
    lake: TableLake,
    files: Sequence[DataFile],
    only: Collection[str] | None = None,
) -> None:
    """The per-type views and ``events`` over the fleet lake's table (:class:`~.lake.TableLake`),
    reading ``files`` (its current data files, damaged ones left out): one ``read_parquet`` of
    a few files per type, however many runs the table holds, with the run's columns ``robot``,
    ``date``, ``run`` and every type's schema (the empty view of a type no file holds too). A remote lake's types are read through its Arrow datasets.
    ``only``, if given, names the views to make (types and ``events``; a remote ``events``
    makes every type's): creating a view binds it, which reads its files' footers. A remote
    lake's files are the ones given: the table is not loaded again (each load reads its log)."""
    by_kind: dict[str, list[DataFile]] = {}
    for f in files:
        by_kind.setdefault(f.kind, []).append(f)
    envelope = ", ".join(quote_ident(f.name) for f in ENVELOPE_COLUMNS)
    types = set(lake.store.registry.types)
    every = [f"{lake.uri}/{f.path}" for kind, fs in by_kind.items() if kind in types for f in fs]
    # ``events`` is the union of the type views where it cannot scan the files at once
    union = lake.remote or not every
    wanted = None if only is None else set(only) | (types if union and "events" in only else set())
    parts = []
    for event_type in lake.store.registry.types:
        view = quote_ident(event_type)
        parts.append(
            f"SELECT robot, date, run, {envelope}, time, {quote_literal(event_type)} AS type "
            f"FROM {view}"
        )
        if wanted is not None and event_type not in wanted:
            continue
        source = fleet_source(con, lake, event_type, by_kind.get(event_type, []))
        if source is not None:
            con.execute(
                f"CREATE OR REPLACE VIEW {view} AS SELECT robot, date, run, {envelope}, "
                f"{view}.*, {_TIME} FROM {source}"
            )
        else:
            empty = pa.Table.from_pylist([], schema=event_schema(event_type, lake.store))
            name = f"_empty_{event_type}"
            con.register(name, empty)
            partitions = ", ".join(f"NULL::{t} AS {n}" for n, t in PARTITION_COLUMNS)
            con.execute(
                f"CREATE OR REPLACE VIEW {view} AS SELECT {partitions}, *, {_TIME} "
                f"FROM {quote_ident(name)}"
            )
    if wanted is not None and "events" not in wanted:
        return
    if union:
        con.execute("CREATE OR REPLACE VIEW events AS " + "\nUNION ALL ".join(parts))
        return
    # One scan of every event type's files (the type from their partition folder): one file's
    # schema to bind instead of every type view's.
    listed = ", ".join(quote_literal(p) for p in sorted(every))
    con.execute(
        f"CREATE OR REPLACE VIEW events AS SELECT robot, date, run, {envelope}, {_TIME}, type "
        f"FROM read_parquet([{listed}], hive_partitioning = true, "
        "hive_types = {'type': 'VARCHAR'}, union_by_name = true)"
    )


def fleet_source(
    con: duckdb.DuckDBPyConnection,
    lake: TableLake,
    kind: str,
    files: Sequence[DataFile],
) -> str | None:
    """What a view reads for the rows of ``kind`` (a ``type`` partition: ``files``), or None
    if none."""
    if not files:
        return None
    if lake.remote:
        name = f"_fleet_{kind}"
        con.register(name, lake.files_dataset(files))
        return quote_ident(name)
    listed = ", ".join(quote_literal(f"{lake.uri}/{f.path}") for f in files)
    # union_by_name: a file holds its own type's columns only (a compacted one may hold all)
    return f"read_parquet([{listed}], hive_partitioning = false, union_by_name = true)"
