"""The digest of a fleet-lake run's rows: a hash of their *values*, so equal values give an equal
digest whatever Arrow buffers hold them, and any changed value another.

A run's ``_run`` row records the digest of its event tables (by type, rows by seq), and a reader
(``replay``, ``where``, ``audit`` from a lake; :meth:`TableLake.read_events`) compares it with
the rows it reads back. The first definition (``sha256:…``, now *version 1*) hashed each slice
of rows as an Arrow IPC stream: the bytes of the buffers, not the values. Rows read back from
Parquet may hold the same values in other buffers — a null struct (``task_started.clock``) comes
back with validity bitmaps on its children, which the rows built from the events lack — so every
run of ``search`` or ``demo`` was refused as damaged. This one (*version 2*,
:data:`DIGEST_PREFIX`) walks each column down to its leaves and hashes, per node, in row order:

* its validity: one byte a row (``1`` valid, ``0`` null), for the rows whose parents are valid;
* a list's length per valid row; then its items as the child node's rows;
* a struct's fields as child nodes, over the struct's valid rows only (what a null struct's
  children hold is no value, so it is not hashed);
* a leaf's valid values: fixed-width ones as their little-endian bytes (a NaN as one NaN),
  strings and binaries as each one's length then all their bytes;

each node and stream in a hash of its own, so how the rows are chunked, sliced or buffered
does not matter. The per-type digest hashes the path, type and streams' hashes of every node
that holds a value in some row (a column null throughout counts as no column: a type that
gains nullable fields keeps its runs' digests); the run's combines the types' (as version 1
did). The definition is part of the lake's format: a
change to it is a new version with a new prefix, and readers keep checking the old ones.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping
from typing import Any, Final

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

#: A version-2 digest: ``values-sha256:<64 hex>``.
DIGEST_PREFIX: Final = "values-sha256:"
#: A version-1 digest (Arrow IPC bytes; written by code before 2026-12): ``sha256:<64 hex>``.
IPC_DIGEST_PREFIX: Final = "sha256:"
#: Rows of one type gathered before they are hashed (fewer, larger steps: a node costs a few
#: Arrow calls whatever its length).
DIGEST_ROWS: Final = 1 << 16


def digest_version(digest: str) -> int | None:
    """The definition ``digest`` was made with (1 or 2), or None for neither."""
    if digest.startswith(DIGEST_PREFIX):
        return 2
    if digest.startswith(IPC_DIGEST_PREFIX):
        return 1
    return None


class _Streams:
    """One SHA-256 per (node path, stream), fed in row order."""

    def __init__(self) -> None:
        self.hashes: dict[tuple[str, str, str], Any] = {}
        #: The nodes with a valid row: only these count (see :meth:`TypeDigest.hexdigest`).
        self.valued: set[str] = set()

    def update(self, path: str, kind: pa.DataType, stream: str, data: bytes | memoryview) -> None:
        key = (path, _type_name(kind), stream)
        h = self.hashes.get(key)
        if h is None:
            h = self.hashes[key] = hashlib.sha256()
        h.update(data)

    def touch(self, path: str, kind: pa.DataType, stream: str) -> None:
        self.update(path, kind, stream, b"")


def _type_name(kind: pa.DataType) -> str:
    """A node's type as the digest names it (nested types by their kind: their children are
    nodes of their own)."""
    if pa.types.is_struct(kind):
        return "struct"
    if pa.types.is_list(kind) or pa.types.is_large_list(kind):
        return "list"
    if pa.types.is_fixed_size_list(kind):
        return "fixed_size_list"
    return str(kind)


def _feed(streams: _Streams, path: str, array: pa.Array) -> None:
    """Hash the rows of ``array`` (every one of them present: its parents valid)."""
    kind = array.type
    if pa.types.is_dictionary(kind):
        array = array.dictionary_decode()
        kind = array.type
    if array.null_count:
        valid = pc.is_valid(array)
        streams.update(path, kind, "valid", np.asarray(valid, dtype=np.uint8).tobytes())
        array = array.filter(valid)
    else:
        streams.update(path, kind, "valid", b"\x01" * len(array))
    if len(array):
        streams.valued.add(path)
    if pa.types.is_null(kind):
        return
    if pa.types.is_struct(kind):
        for i in range(kind.num_fields):
            _feed(streams, f"{path}.{kind.field(i).name}", array.field(i))
        return
    if pa.types.is_list(kind) or pa.types.is_large_list(kind):
        lengths = pc.list_value_length(array).cast(pa.int64())
        streams.update(path, kind, "lengths", _little(lengths.to_numpy(zero_copy_only=False)))
        _feed(streams, f"{path}[]", array.flatten())
        return
    if pa.types.is_fixed_size_list(kind):
        _feed(streams, f"{path}[]", array.flatten())
        return
    if (
        pa.types.is_string(kind)
        or pa.types.is_large_string(kind)
        or pa.types.is_binary(kind)
        or pa.types.is_large_binary(kind)
    ):
        _feed_bytes(streams, path, array)
        return
    if pa.types.is_boolean(kind):
        values = array.to_numpy(zero_copy_only=False).astype(np.uint8)
        streams.update(path, kind, "values", values.tobytes())
        return
    if pa.types.is_floating(kind):
        values = array.to_numpy(zero_copy_only=False)
        nan = np.isnan(values)
        if nan.any():  # every NaN as one NaN: the payload bits of a NaN are no value
            values = np.where(nan, math.nan, values).astype(values.dtype)
        streams.update(path, kind, "values", _little(values))
        return
    if pa.types.is_primitive(kind):  # integers, dates, times, timestamps, durations
        width = kind.bit_width // 8
        view = array.view(pa.int64() if width == 8 else pa.int32() if width == 4 else kind)
        streams.update(path, kind, "values", _little(view.to_numpy(zero_copy_only=False)))
        return
    # Any other type (none of the lake's schemas has one): its values as Python sees them.
    text = repr(array.to_pylist()).encode()
    streams.update(path, kind, "values", len(text).to_bytes(8, "little") + text)


def _feed_bytes(streams: _Streams, path: str, array: pa.Array) -> None:
    large = pa.types.is_large_string(array.type) or pa.types.is_large_binary(array.type)
    _, offsets_buffer, data = array.buffers()
    offsets = np.frombuffer(
        offsets_buffer, dtype=np.int64 if large else np.int32, count=array.offset + len(array) + 1
    )[array.offset :]
    streams.update(path, array.type, "lengths", _little(np.diff(offsets).astype(np.int64)))
    if len(array) and data is not None:
        streams.update(path, array.type, "bytes", memoryview(data)[offsets[0] : offsets[-1]])


def _little(values: np.ndarray[Any, Any]) -> bytes:
    return values.astype(values.dtype.newbyteorder("<"), copy=False).tobytes()


class TypeDigest:
    """The version-2 digest of one type's rows, fed in any chunks (see the module); rows are
    hashed once ``gather`` of them have come (0: as they come; a reader that streams a run
    keeps no more of it than it must)."""

    def __init__(self, *, gather: int = DIGEST_ROWS) -> None:
        self._streams = _Streams()
        self._pending: list[pa.Table] = []
        self._rows = 0
        self._gather = gather

    def add(self, table: pa.Table) -> None:
        self._pending.append(table)
        self._rows += table.num_rows
        if self._rows >= self._gather:
            self._flush()

    def _flush(self) -> None:
        pending, self._pending, self._rows = self._pending, [], 0
        for table in pending:
            for field, column in zip(table.schema, table.columns, strict=True):
                for chunk in column.chunks or [pa.array([], field.type)]:
                    _feed(self._streams, field.name, chunk)

    def hexdigest(self) -> str:
        """The hex digest of every node that holds a value in some row: a column null in every
        row counts as no column, so a run's digest does not change when its type gains a
        version with new (nullable) fields that its rows read back as null; a value set to
        null where it was the column's only one still removes a node the commit counted."""
        self._flush()
        h = hashlib.sha256()
        for (path, kind, stream), digest in sorted(self._streams.hashes.items()):
            if path in self._streams.valued:
                h.update(f"{path}\0{kind}\0{stream}\0{digest.hexdigest()}\n".encode())
        return h.hexdigest()


class RunDigest:
    """The version-2 digest of a run's event tables, fed a type's rows at a time."""

    def __init__(self) -> None:
        self._types: dict[str, TypeDigest] = {}

    def add(self, event_type: str, table: pa.Table) -> None:
        self._types.setdefault(event_type, TypeDigest()).add(table)

    def hexdigest(self) -> str:
        return DIGEST_PREFIX + combine({t: d.hexdigest() for t, d in self._types.items()})


def combine(per_type: Mapping[str, str]) -> str:
    """The run's hash (hex) of its types' hashes."""
    h = hashlib.sha256()
    for event_type in sorted(per_type):
        h.update(f"{event_type}\0{per_type[event_type]}\n".encode())
    return h.hexdigest()


def values_digest(tables: Mapping[str, pa.Table]) -> str:
    """The version-2 digest of a run's event tables (conformed to their schemas, by seq)."""
    run = RunDigest()
    for event_type, table in tables.items():
        run.add(event_type, table)
    return run.hexdigest()


__all__ = [
    "DIGEST_PREFIX",
    "DIGEST_ROWS",
    "IPC_DIGEST_PREFIX",
    "RunDigest",
    "TypeDigest",
    "combine",
    "digest_version",
    "values_digest",
]
