"""DuckDB over the lake: one view per event type, and ``events`` with every event's envelope.

Views read the Parquet files in place (nothing is copied into DuckDB) with the partition columns
``robot`` (VARCHAR), ``date`` (DATE) and ``run`` (VARCHAR) added. A type without any file in the
lake still gets its view, empty but with its typed columns, so queries never depend on which
event types happen to have occurred.
"""

from __future__ import annotations

from typing import Final

import duckdb
import pyarrow as pa

from .arrow import ENVELOPE_COLUMNS, event_schema
from .lake import Lake
from .schemas import default_registry

PARTITION_COLUMNS: Final = (("robot", "VARCHAR"), ("date", "DATE"), ("run", "VARCHAR"))
HIVE_TYPES: Final = "{" + ", ".join(f"'{n}': '{t}'" for n, t in PARTITION_COLUMNS) + "}"


def quote_ident(name: str) -> str:
    return '"' + name.replace('"', '""') + '"'


def quote_literal(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"


def connect(lake: Lake, *, database: str = ":memory:") -> duckdb.DuckDBPyConnection:
    """A DuckDB connection with the lake's views (in an in-memory database by default)."""
    con = duckdb.connect(database)
    create_type_views(con, lake)
    return con


def create_type_views(con: duckdb.DuckDBPyConnection, lake: Lake) -> None:
    present = set(lake.event_types())
    envelope = ", ".join(quote_ident(f.name) for f in ENVELOPE_COLUMNS)
    parts = []
    for event_type in default_registry().types:
        view = quote_ident(event_type)
        if event_type in present:
            pattern = str(lake.root / "robot=*" / "date=*" / "run=*" / f"{event_type}.parquet")
            source = (
                f"read_parquet({quote_literal(pattern)}, hive_partitioning = true, "
                f"hive_types = {HIVE_TYPES}, union_by_name = true)"
            )
            con.execute(f"CREATE OR REPLACE VIEW {view} AS SELECT * FROM {source}")
        else:
            empty = pa.Table.from_pylist([], schema=event_schema(event_type))
            name = f"_empty_{event_type}"
            con.register(name, empty)
            partitions = ", ".join(f"NULL::{t} AS {n}" for n, t in PARTITION_COLUMNS)
            con.execute(
                f"CREATE OR REPLACE VIEW {view} AS SELECT *, {partitions} FROM {quote_ident(name)}"
            )
        parts.append(
            f"SELECT robot, date, run, {envelope}, {quote_literal(event_type)} AS type FROM {view}"
        )
    con.execute("CREATE OR REPLACE VIEW events AS " + "\nUNION ALL ".join(parts))
