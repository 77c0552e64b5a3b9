"""The fleet lake's table itself (:class:`LakeBase`): where it is, its Delta table, its data
files, and storing and deleting them; what every layer of :class:`~objsearch.events.lake.fleet.TableLake`
stands on."""

from __future__ import annotations

import hashlib
import time
from collections.abc import Mapping, Sequence
from contextlib import suppress
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.dataset as pds
import pyarrow.fs as pafs
import pyarrow.parquet as pq

from .. import _fs
from ..store import Store
from .common import ROW_GROUP_ROWS
from .schema import TABLE_DIR, TABLE_FORMAT, DataFile, TableLakeError, read_schema, table_schema
from .storage import _filesystem, _hashed_name, _stats, file_sha256, storage_options
from .transactions import IDENTITY_INDEX_APP, STAMP_INDEX_APP


def is_table_lake(root: Path | str) -> bool:
    """Whether ``root`` holds a fleet lake (a Delta table at ``root/events``)."""
    text = str(root)
    if "://" in text:
        from deltalake import DeltaTable

        return bool(DeltaTable.is_deltatable(f"{text.rstrip('/')}/{TABLE_DIR}", storage_options()))
    return (Path(root) / TABLE_DIR / "_delta_log").is_dir()


class LakeBase:
    """The fleet lake at ``root`` (a folder or an ``s3://`` URI): its table and its files."""

    def __init__(self, root: Path | str, *, store: Store) -> None:
        #: What the lake's events are: their types, Arrow schemas, upcasters, derived tables:
        #: required, so no lake is opened that silently derives none of a domain's tables.
        self.store = store
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

    def listing(self) -> Any:
        """The table at its latest version for a reader of its files: read from its log
        without delta-rs (:mod:`.log_listing`: a local table whose log is its JSON commits,
        about 30 MB less memory), else :meth:`table`."""
        if not self.remote:
            from .log_listing import read_listing

            listing = read_listing(self.uri, self.root)
            if listing is not None:
                return listing
        return self.table()

    def create(self) -> None:
        """Create the (empty) table if it does not exist; safe to race with other writers."""
        from deltalake import write_deltalake

        if self.exists():
            return
        if not self.remote:
            _fs.make_dirs(Path(self.uri).parent)
        from deltalake import CommitProperties, Transaction
        from deltalake.exceptions import DeltaError

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
        except (DeltaError, OSError):
            # Another writer created it first (delta-rs refuses a second version 0); anything
            # else is no lost race and propagates even once the table exists.
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

    def _source(self, rel: str) -> tuple[str, Any]:
        """A data file's path and file system, as Arrow's readers take them."""
        if self.remote:
            fs, base = _filesystem(self.uri)
            return f"{base}/{rel}", fs
        return str(Path(self.uri) / rel), pafs.LocalFileSystem()
