"""A run's digests as the fleet lake records them: the values digest (version 2,
:mod:`.run_digest`) of a run's tables or of its events streamed, and the version-1 digest (Arrow
IPC bytes) kept to check the runs committed with it."""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Iterator, Mapping
from typing import Any, Final

import pyarrow as pa

from ..arrow import ENVELOPE_COLUMNS, event_schema, events_to_tables, payload_schema
from ..envelope import Event
from ..store import Store
from .common import _conform
from .run_digest import RunDigest, values_digest
from .storage import CHUNK_EVENTS

#: Rows of one event type hashed at a time by :func:`ipc_digest` (the version-1 digest, kept to
#: check the runs committed with it; version 2 is :mod:`.run_digest`).
DIGEST_ROWS: Final = 1 << 16


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
