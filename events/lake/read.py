"""Reading the fleet lake: its runs' records (``_run`` rows), a run's tables and events checked
against what its commit recorded, and which data files a query may read (:class:`LakeReads`)."""

from __future__ import annotations

import itertools
import json
import logging
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc

from ..arrow import ENVELOPE_COLUMNS, event_schema, tables_to_events
from ..envelope import Event
from ..errors import EventStoreError
from .common import parquet_problem
from .digests import _combine, _ipc_type_digest, committed_schema, ipc_digest, table_digest
from .run_digest import DIGEST_PREFIX, digest_version
from .schema import (
    _RECORD_ERRORS,
    RUN_COLUMN,
    RUN_TYPE,
    DataFile,
    TableLakeError,
    TableRun,
    _run_of,
)
from .storage import _hash_mismatch, file_sha256
from .table import LakeBase
from .transactions import IDENTITY_INDEX_APP, _app_id, _identity_app
from .verified import Identity, VerifiedFiles, sha256_file

_log = logging.getLogger(__name__)


class LakeReads(LakeBase):
    """The fleet lake, read: its runs, a run's rows, the files a query may read."""

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

    def rows_outside_runs(self, kind: str, table: Any | None = None) -> list[TableRun]:
        """The rows :meth:`~objsearch.events.lake.commit.LakeCommits.commit_outside_runs` kept
        in the partition ``kind``, each as the description it was given (with its commit token),
        in no particular order."""
        table = self.table() if table is None else table
        columns = ["robot", "date", "run", "commit", RUN_COLUMN]
        return [
            _run_of(r) for r in self._dataset(table, [kind]).to_table(columns=columns).to_pylist()
        ]

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
        and again only once its ``stat`` identity changes (:mod:`.verified`: a
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
