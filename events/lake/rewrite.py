"""Rewriting the fleet lake's data files: a run replaced or removed (its files' other rows
written again), and compaction (:class:`LakeRewrites`), every file content-addressed."""

from __future__ import annotations

import hashlib
import logging
import math
import random
import time
import uuid
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from .. import _fs
from .checks import LakeChecks
from .common import parquet_problem
from .head import record_head
from .schema import DataFile, TableLakeError, table_schema
from .storage import _filesystem, _hash_mismatch, _token, file_sha256
from .stream_file import _StreamFile, abandon
from .transactions import COMMIT_TRIES, _app_id, _rewrite_transaction
from .verified import sha256_file

_log = logging.getLogger(__name__)

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


class LakeRewrites(LakeChecks):
    """The fleet lake, its files rewritten: runs replaced or removed, compaction."""

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
            record_head(self, int(table.version()) + 1)
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
                abandon(self, [out])
                return None
            return out.close()
        except BaseException:
            abandon(self, [out])
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
        record_head(self, int(table.version()))
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


def _claim_ns(table: Any) -> int | None:
    """When the table's latest compaction claim was made (ns since the epoch), if any."""
    claim = str(table.metadata().configuration.get(COMPACTION_CLAIM) or "")
    head = claim.partition("-")[0]
    return int(head) if head.isdigit() else None
