"""What the lake shares with its writers and readers: its error, the rules for robot and run names
and dates, a table's conformance to its event type's schema, the row-group size, and the cheap
check that a Parquet file is whole.

The lake itself is the fleet lake (:class:`objsearch.events.lake.TableLake`, ``objsearch.lake/2``); the
per-run-folder lake that came before it (``objsearch.lake/1``) is read only to migrate it
(:mod:`objsearch.events.lake.folder_v1`).
"""

from __future__ import annotations

import datetime as dt
import os
import re
from pathlib import Path
from typing import Final

import pyarrow as pa

from ..arrow import event_schema
from ..errors import EventStoreError
from ..store import Store

_NAME: Final = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")
#: Rows per Parquet row group: small enough that a seq range skips most of a 1 M-event run and
#: that DuckDB has several units of work per file, large enough to compress well.
ROW_GROUP_ROWS: Final = 1 << 17


class LakeError(EventStoreError):
    """The lake cannot do what was asked (bad name, run exists with other content, …)."""


def _conform(event_type: str, table: pa.Table, store: Store) -> pa.Table:
    schema = event_schema(event_type, store)
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


def parquet_problem(path: Path) -> str | None:
    """Why ``path`` is not a whole Parquet file (by its ends alone), or None."""
    try:
        with path.open("rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            if size == 0:
                return f"{path.name} is empty"
            head = fh.read(4)
            fh.seek(max(0, size - 8))
            tail = fh.read(8)
    except OSError as exc:
        return f"{path.name}: {exc.strerror or exc}"
    if size < 12 or head != b"PAR1" or tail[4:] != b"PAR1":
        return f"{path.name} is truncated or not Parquet ({size} bytes, no PAR1 at both ends)"
    if int.from_bytes(tail[:4], "little") > size - 12:
        return f"{path.name} is truncated (its footer is longer than the file)"
    return None


def _check_name(what: str, value: str) -> None:
    if not (isinstance(value, str) and _NAME.fullmatch(value)):
        raise LakeError(
            f"{what} name {value!r} must start with a letter or digit and hold only letters, "
            "digits, '.', '_' and '-' (it names the run in the table and in its log's transactions)"
        )


def _check_date(value: str | dt.date) -> str:
    try:
        day = value if isinstance(value, dt.date) else dt.date.fromisoformat(value)
    except (TypeError, ValueError):
        raise LakeError(f"date {value!r} is not an ISO date (YYYY-MM-DD)") from None
    return day.isoformat()
