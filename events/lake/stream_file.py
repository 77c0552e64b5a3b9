"""A data file of the fleet lake written as its rows arrive, hashed as it is written, and named
after its hash when closed (:class:`_StreamFile`)."""

from __future__ import annotations

import hashlib
import io
import time
from collections.abc import Iterable
from contextlib import suppress
from typing import TYPE_CHECKING, Any, Final, NamedTuple

import pyarrow as pa
import pyarrow.parquet as pq

from .common import ROW_GROUP_ROWS
from .schema import file_schema
from .storage import CHUNK_EVENTS, _hashed_name, _merge, _stats

if TYPE_CHECKING:
    from .table import LakeBase

#: A streamed data file stays in memory until its bytes pass this, then goes on in a temporary
#: file: a smaller one is stored once, under its final name (one durable step, not three: the
#: kill tests' and a short run's cost), and the ~16 files of a long run hold at most this each.
SPILL_BYTES: Final = 1 << 20


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
        lake: LakeBase,
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


class _Named(NamedTuple):
    path: str


def abandon(lake: LakeBase, files: Iterable[_StreamFile]) -> None:
    """Close and delete files a failed commit of ``lake`` was writing."""
    files = list(files)
    # What closing a half-written file raises (Arrow's errors, the storage's OSError) must not
    # replace the failed commit's own error; the files are deleted below anyway.
    for f in files:
        with suppress(OSError, pa.ArrowException):
            f.writer.close()
        if f.out is not None:
            with suppress(OSError, pa.ArrowException):
                lake._close(f.rel, f.out)
    lake._delete_files([_Named(f.rel) for f in files if f.on_storage])
