"""The analytics lake: typed Parquet per event type, partitioned by robot / date / run.

Layout (Hive-style, readable by DuckDB, polars, pyarrow and any Parquet reader)::

    LAKE/robot=<robot>/date=<YYYY-MM-DD>/run=<run>/<event_type>.parquet
    LAKE/robot=<robot>/date=<YYYY-MM-DD>/run=<run>/_run.json      what the run holds
    LAKE/robot=<robot>/date=<YYYY-MM-DD>/run=<run>/_derived/<name>.v<version>.parquet
    LAKE/.staging/                                               runs being written
    LAKE/.writer                                                 pid of the last writer (a hint)

A run is committed whole and atomically: its files are written and fsync'ed in a staging
directory, then the directory is renamed into place, so a reader (or a crash) sees all of a run
or none of it. Committing the same content again is a no-op (its digest matches), so re-running
an import never duplicates — unless the committed run fails its file digests, which it then
rewrites whole by the replace path below; different content for an existing run needs
``replace=True``.

Writers hold the lake's lock (an ``flock`` on the lake directory itself) for the whole commit; a
second writer waits for it, up to ``lock_wait_s``, then fails with :class:`LakeBusyError`. Whoever
takes the lock first finishes what a killed writer left (:meth:`Lake.recover`): a replace is
rolled forward from its intent record, and every other entry of ``.staging`` (a half-written run,
the trash of a finished replace) is removed. A replace is: stage the new run; write the intent
``.staging/<id>.replace.json`` (the commit point: before it the old run stays, after it the new
run wins); rename the old run into ``.staging``; rename the new one into place; drop the old one
and the intent. At every instant a complete old or new run exists, and the intent says which.

Each event table is written sorted by ``seq`` in row groups of 128 Ki rows, so a reader
filtering on ``seq`` can skip row groups by their min/max statistics. Next to the events, a
commit writes the run's derived tables (:mod:`objsearch.events.derived`: per-task summaries and
those the installed catalogue hands over, the agent's Eq. 4 rows), computed from that run's tables
alone; they are not part of the digest (they are a function of it), and committing the same
content again writes any that are missing or of an older version, which is how a lake written by
older code is upgraded (:meth:`Lake.upgrade` does it for every run).

Every file a commit writes is recorded in the run's manifest with its size and SHA-256, and the
manifest carries the SHA-256 of its own content (:mod:`objsearch.events.lake_digest`); Parquet
files are written with page checksums. :meth:`Lake.scan` checks sizes (cheap, for listings),
``scan(check_digests=True)`` every byte (what queries do before building their views), and
:meth:`Lake.verify` reports every damaged file. A run committed before digests existed has none:
it is read as before (its Parquet ends checked, and decoded in full by ``verify``) until
:meth:`Lake.upgrade`, or committing the same content again, records them.

The lake is where anything that produces events lands: :func:`compact_log` seals an event log
into it, and other importers (e.g. ROS bags) call :meth:`Lake.commit_events` or
:meth:`Lake.commit_tables` directly.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import hashlib
import json
import logging
import os
import re
import shutil
import time
import uuid
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import pyarrow as pa
import pyarrow.parquet as pq

from . import _fs
from .arrow import event_schema, events_to_tables, tables_to_events
from .derived import DERIVED_DIR, DerivedTable, derive_run, derived_tables
from .envelope import Event, deterministic_event_id
from .errors import EventStoreError
from .lake_digest import (
    FILES_KEY,
    SELF_KEY,
    FileDigest,
    bytes_digest,
    file_digests,
    manifest_digest,
    mismatch,
    parse_files,
)
from .log_files import LOCK_FILE, read_meta
from .log_read import read_log
from .store import Store, shipped

LAKE_FORMAT: Final = "objsearch.lake/1"
RUN_FILE: Final = "_run.json"
STAGING: Final = ".staging"
WRITER_HINT: Final = ".writer"
INTENT_SUFFIX: Final = ".replace.json"
#: How long a writer waits for another commit to release the lake by default.
LOCK_WAIT_S: Final = 30.0
_NAME: Final = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")
_ATTACHMENT: Final = re.compile(r"_[A-Za-z0-9][A-Za-z0-9._-]*")
_log = logging.getLogger(__name__)
#: Rows per Parquet row group: small enough that a seq range skips most of a 1 M-event run and
#: that DuckDB has several units of work per file, large enough to compress well.
ROW_GROUP_ROWS: Final = 1 << 17


class LakeError(EventStoreError):
    """The lake cannot do what was asked (bad name, run exists with other content, …)."""


class LakeBusyError(LakeError):
    """Another commit held the lake's lock for longer than this writer would wait."""


@dataclass(frozen=True, slots=True)
class DamagedRun:
    """A run folder readers leave out: its manifest or one of its files is not whole."""

    path: Path
    reason: str
    #: Each damaged file and why (``reason`` joins them); empty when built from a reason alone.
    problems: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class LakeCheck:
    """What :meth:`Lake.verify` found."""

    runs: int  # run folders
    files: int  # files of the healthy runs, read whole (hashed, or decoded if without digests)
    bytes: int  # their size
    damaged: list[DamagedRun]
    #: Runs committed before file digests (older code): decoded in full instead of hashed.
    unverified: list[Path]


@dataclass(frozen=True, slots=True)
class RunInfo:
    """One committed run: where it is and what it holds (the contents of its ``_run.json``)."""

    robot: str
    date: str
    run: str
    path: Path
    rows: Mapping[str, int]  # event type → rows
    digest: str
    source: str
    #: What the run is a record of, when the importer knows: ``run_id`` (the agent run's id, from
    #: an event log's meta.json or proven by a bag's events) and ``first_event_id``. The lake
    #: uses it to refuse the same agent run under a second name.
    identity: Mapping[str, str] = dataclasses.field(default_factory=dict)
    #: Size and digest of every file the commit wrote, by run-relative path (empty: a run
    #: committed before digests existed).
    files: Mapping[str, FileDigest] = dataclasses.field(default_factory=dict)
    #: The derived tables a run of this lake has (its store's: ``derived_tables(store)``).
    derived: tuple[DerivedTable, ...] = ()

    @property
    def events(self) -> int:
        return sum(self.rows.values())

    def missing_derived(self) -> list[DerivedTable]:
        """Derived tables this run lacks at their current version (older code wrote it). In a
        run with digests, a file its manifest does not list (an upgrade killed between writing
        it and recording it) counts as missing: readers compute those rows from the events."""
        return [
            d
            for d in self.derived
            if not d.path(self.path).is_file()
            or (self.files and _relative(d.path(self.path), self.path) not in self.files)
        ]


class Lake:
    """A directory of committed runs. Cheap to create; nothing is read until asked."""

    def __init__(
        self, root: Path | str, *, lock_wait_s: float = LOCK_WAIT_S, store: Store | None = None
    ) -> None:
        #: What the lake's events are: their types, Arrow schemas, upcasters, derived tables.
        self.store = store or shipped()
        self.derived = derived_tables(self.store)
        self.root = Path(root)
        self.lock_wait_s = lock_wait_s
        self._lock_depth = 0

    def __repr__(self) -> str:
        return f"Lake({str(self.root)!r})"

    # -- reading --------------------------------------------------------------------------------

    def runs(self) -> list[RunInfo]:
        """Every committed run, sorted by (robot, date, run)."""
        found = [
            _read_run_file(p, self.derived)
            for p in sorted(self.root.glob(f"robot=*/date=*/run=*/{RUN_FILE}"))
        ]
        return sorted(found, key=lambda r: (r.robot, r.date, r.run))

    def find(self, robot: str, run: str) -> RunInfo | None:
        """The run ``run`` of ``robot``, whatever its date, or None."""
        matches = [
            _read_run_file(p, self.derived)
            for p in self.root.glob(f"robot={robot}/date=*/run={run}/{RUN_FILE}")
        ]
        if len(matches) > 1:
            raise LakeError(f"{self.root}: run {run!r} of robot {robot!r} is under two dates")
        return matches[0] if matches else None

    def files(self, event_type: str) -> list[Path]:
        """The Parquet files of ``event_type`` across all runs."""
        return sorted(self.root.glob(f"robot=*/date=*/run=*/{event_type}.parquet"))

    def read_events(self, run: RunInfo) -> list[Event]:
        """Every event of one committed run, as :class:`Event` (latest versions), by (stream, seq).

        A run committed by older code stores an older version of some types (its files are never
        rewritten); they are upcast here, as ``read_log`` does."""
        upcast = self.store.upcaster.upcast
        tables = self.read_tables(run).values()
        return [upcast(e) for e in tables_to_events(tables, self.store)]

    def read_tables(self, run: RunInfo) -> dict[str, pa.Table]:
        """The event tables of one committed run as stored (one per type in its manifest), each
        checked against its recorded digest and its page checksums; raises :class:`LakeError`
        naming a damaged file."""
        return {
            event_type: _read_parquet(
                run.path / f"{event_type}.parquet", run.files.get(f"{event_type}.parquet")
            )
            for event_type in sorted(run.rows)
        }

    def scan(
        self,
        *,
        check_digests: bool = False,
        progress: Callable[[list[Path]], Iterable[Path]] | None = None,
    ) -> tuple[list[RunInfo], list[DamagedRun]]:
        """The runs readers can use, and the run folders they must leave out.

        A run is left out if its manifest is unreadable, fails its own digest or names another
        folder than the one it is in; if a file it lists is missing or has another size; if a
        Parquet file is truncated (no ``PAR1`` magic at both ends, or a footer longer than the
        file); or if an event table it does not list lies in its folder. That reads 8 bytes a
        file. ``check_digests`` also hashes every file a manifest lists (what queries do: DuckDB
        does not check page checksums, so a flipped bit inside a file would change an answer);
        a run without digests (older code) gets only the cheap check, and a full footer parse
        (:func:`deep_check`) when a view over it fails. ``progress`` wraps the files as they are
        hashed.
        """
        infos: list[RunInfo] = []
        damaged: list[DamagedRun] = []
        for folder in sorted(self.root.glob("robot=*/date=*/run=*")):
            if not folder.is_dir():
                continue
            try:
                infos.append(_read_run_file(folder / RUN_FILE, self.derived))
            except LakeError as exc:
                damaged.append(DamagedRun(folder, str(exc), (str(exc),)))
        hashed = (
            file_digests((r.path / name for r in infos for name in r.files), progress)
            if check_digests
            else None
        )
        runs: list[RunInfo] = []
        for info in infos:
            problems = _run_problems(info, hashed)
            if problems:
                damaged.append(DamagedRun(info.path, "; ".join(problems), tuple(problems)))
            else:
                runs.append(info)
        runs.sort(key=lambda r: (r.robot, r.date, r.run))
        damaged.sort(key=lambda d: d.path)
        return runs, damaged

    def verify(self, progress: Callable[[list[Path]], Iterable[Path]] | None = None) -> LakeCheck:
        """Read every byte of every run: hash each file its manifest lists, and decode in full
        (checking page checksums where a file has them) the files of runs without digests.
        Changes nothing. ``progress`` wraps the files as they are hashed (the CLI's progress
        line)."""
        runs, damaged = self.scan(check_digests=True, progress=progress)
        folders = len(runs) + len(damaged)
        unverified = [r for r in runs if not r.files]
        files = sum(len(r.files) for r in runs)
        size = sum(f.size for r in runs for f in r.files.values())
        for run in unverified:
            paths = _parquet_files(run)
            problems = [p for p in (_decode_problem(path) for path in paths) if p is not None]
            if problems:
                damaged.append(DamagedRun(run.path, "; ".join(problems), tuple(problems)))
            else:
                files += len(paths)
                size += sum(p.stat().st_size for p in paths)
        damaged.sort(key=lambda d: d.path)
        bad = {d.path for d in damaged}
        return LakeCheck(
            runs=folders,
            files=files,
            bytes=size,
            damaged=damaged,
            unverified=[r.path for r in unverified if r.path not in bad],
        )

    def upgrade(
        self, progress: Callable[[list[RunInfo]], Iterable[RunInfo]] | None = None
    ) -> list[RunInfo]:
        """Bring every healthy run written by older code up to date: write the derived tables it
        lacks, and record its files' digests if it has none (after decoding every file in full:
        digests of damaged bytes would only vouch for the damage). Returns the runs upgraded.
        Idempotent; each file and the manifest appear atomically, so readers never see half.
        ``progress`` wraps the runs as they are looked at (the CLI's progress line)."""
        upgraded = []
        with self.locked():
            runs, damaged = self.scan()
            for bad in damaged:
                _log.warning("%s: damaged run not upgraded: %s", bad.path, bad.reason)
            for info in progress(runs) if progress else runs:
                stale = info.missing_derived() or not info.files
                if stale and self._upgrade_run(info, None):
                    upgraded.append(info)
        return upgraded

    def _upgrade_run(self, info: RunInfo, tables: Mapping[str, pa.Table] | None) -> bool:
        """Record a run's digests if it has none and write the derived tables it lacks."""
        if not info.files:
            problems = [p for p in map(_decode_problem, _parquet_files(info)) if p is not None]
            if problems:
                _log.warning("%s: damaged run not upgraded: %s", info.path, "; ".join(problems))
                return False
            info = _record_digests(info)
        if info.missing_derived():
            _write_derived(
                info.path, self.read_tables(info) if tables is None else tables, info, self.store
            )
        return True

    def event_types(self) -> list[str]:
        """Event types with at least one file in the lake."""
        return sorted({p.stem for p in self.root.glob("robot=*/date=*/run=*/*.parquet")})

    # -- writing --------------------------------------------------------------------------------

    def commit_events(
        self,
        events: Iterable[Event],
        *,
        robot: str,
        run: str,
        date: str | dt.date | None = None,
        source: str = "",
        replace: bool = False,
        identity: Mapping[str, str] | None = None,
    ) -> RunInfo:
        """Commit events (any versions; upcast to latest) as one run.

        ``date`` defaults to the UTC day of the first event's ``recorded_at_ns``.
        """
        first: list[Event] = []

        def remember(stream: Iterable[Event]) -> Iterable[Event]:
            for event in stream:
                if not first:
                    first.append(event)
                yield event

        tables = events_to_tables(remember(events), self.store)
        if date is None:
            if not first:
                raise LakeError("an empty run needs an explicit date")
            date = dt.datetime.fromtimestamp(first[0].recorded_at_ns / 1e9, dt.UTC).date()
        return self.commit_tables(
            tables,
            robot=robot,
            run=run,
            date=date,
            source=source,
            replace=replace,
            identity=identity,
        )

    def commit_tables(
        self,
        tables: Mapping[str, pa.Table],
        *,
        robot: str,
        run: str,
        date: str | dt.date,
        source: str = "",
        replace: bool = False,
        attachments: Mapping[str, bytes] | None = None,
        identity: Mapping[str, str] | None = None,
    ) -> RunInfo:
        """Commit one table per event type as one run, atomically. Tables must match
        :func:`event_schema` of their type (columns may be cast, not missing).

        ``attachments`` are files (name → bytes, names starting with ``_``) committed in the run's
        folder with it, e.g. an importer's report; they are not part of the digest.
        ``identity`` (see :attr:`RunInfo.identity`) goes into the manifest.
        """
        attachments = attachments or {}
        _check_name("robot", robot)
        _check_name("run", run)
        for name in attachments:
            if not (_ATTACHMENT.fullmatch(name) and name != RUN_FILE):
                raise LakeError(f"attachment name {name!r} must be '_' then letters, digits, '.-_'")
        day = _check_date(date)
        checked = {t: _conform(t, table, self.store) for t, table in sorted(tables.items())}
        digest = _digest(checked)
        with self.locked():
            existing = self.find(robot, run)
            if existing is not None:
                same = existing.digest == digest and existing.date == day
                damage = _damage(existing) if same else []
                if same and not damage:
                    # The same run again: nothing to do but add what older code did not write
                    # (derived tables, the files' digests).
                    if existing.missing_derived() or not existing.files:
                        self._upgrade_run(existing, checked)
                        return _read_run_file(existing.path / RUN_FILE, self.derived)
                    return existing
                if damage:
                    # The same content over a damaged copy: write it whole again (a replace).
                    _log.warning(
                        "%s: rewriting the damaged run from the same content: %s",
                        existing.path,
                        "; ".join(damage),
                    )
                elif not replace:
                    raise LakeError(
                        f"{existing.path} already holds run {run!r} of robot {robot!r} with "
                        "other content; pass replace=True to replace it"
                    )
            final = self.root / f"robot={robot}" / f"date={day}" / f"run={run}"
            token = uuid.uuid4().hex
            staged = self.root / STAGING / token
            manifest = {
                "format": LAKE_FORMAT,
                "robot": robot,
                "date": day,
                "run": run,
                "rows": {t: table.num_rows for t, table in checked.items()},
                "digest": digest,
                "source": source,
            }
            if identity:
                manifest["identity"] = dict(sorted(identity.items()))
            _fs.make_dirs(staged)
            try:
                _stage(staged, checked, manifest, attachments, self.store)
            except BaseException:
                shutil.rmtree(staged, ignore_errors=True)
                raise
            _fs.make_dirs(final.parent)
            if existing is None:
                _fs.rename(staged, final)
                _fs.fsync_dir(final.parent)
                _fs.fsync_dir(staged.parent)
            else:
                intent = {
                    "staged": token,
                    "final": str(final.relative_to(self.root)),
                    "old": str(existing.path.relative_to(self.root)),
                    "trash": f"old-{token}",
                }
                intent_path = self.root / STAGING / f"{token}{INTENT_SUFFIX}"
                _fs.write_atomic(intent_path, _json_bytes(intent))
                self._roll_forward(intent_path)
            return _read_run_file(final / RUN_FILE, self.derived)

    def remove_run(self, info: RunInfo) -> None:
        """Take a committed run out of the lake (e.g. a piece merged into its session's run):
        renamed into ``.staging`` (readers stop seeing it at once), then deleted; a kill
        between the two leaves it to :meth:`recover`."""
        with self.locked():
            trash = self.root / STAGING / f"removed-{uuid.uuid4().hex}"
            _fs.make_dirs(trash.parent)
            _fs.rename(info.path, trash)
            _fs.fsync_dir(info.path.parent)
            _fs.fsync_dir(trash.parent)
            shutil.rmtree(trash)
            _fs.fsync_dir(trash.parent)

    def holding(self, identity: Mapping[str, str]) -> list[RunInfo]:
        """The runs whose recorded identity shares a value with ``identity`` (the same agent
        run, or the same first event)."""
        wanted = {(k, v) for k, v in identity.items() if v}
        return [r for r in self.runs() if wanted & set(r.identity.items())]

    # -- the lock and recovery ------------------------------------------------------------------

    @contextmanager
    def locked(self) -> Iterator[None]:
        """Hold the lake's writer lock (re-entrant on this object), after finishing or removing
        whatever a killed writer left (:meth:`recover`). Waits up to ``lock_wait_s`` for
        another writer, saying so once on the log, then raises :class:`LakeBusyError`."""
        if self._lock_depth:
            self._lock_depth += 1
            try:
                yield
            finally:
                self._lock_depth -= 1
            return
        _fs.make_dirs(self.root)
        fd = self._acquire()
        self._lock_depth = 1
        try:
            with suppress(OSError):  # only a hint for the "busy" message
                (self.root / WRITER_HINT).write_text(f"{os.getpid()}\n", encoding="ascii")
            self._recover_locked()
            yield
        finally:
            self._lock_depth = 0
            os.close(fd)

    def recover(self) -> bool:
        """Finish or undo what killed writers left, if no writer holds the lake now; returns
        whether it could look (False: a live writer holds the lock and will do it)."""
        if not self.root.is_dir():
            return True
        if self._lock_depth:
            self._recover_locked()
            return True
        fd = _fs.try_lock_dir(self.root)
        if fd is None:
            return False
        try:
            self._recover_locked()
        finally:
            os.close(fd)
        return True

    def needs_recovery(self) -> bool:
        """Whether a killed writer left anything in ``.staging`` (cheap: one directory listing)."""
        staging = self.root / STAGING
        return staging.is_dir() and any(staging.iterdir())

    def _acquire(self) -> int:
        fd = _fs.try_lock_dir(self.root)
        if fd is not None:
            return fd
        deadline = time.monotonic() + self.lock_wait_s
        if self.lock_wait_s > 0:
            _log.warning(
                "%s: another commit holds the lake%s; waiting up to %g s for it",
                self.root,
                self._holder_hint(),
                self.lock_wait_s,
            )
        while time.monotonic() < deadline:
            time.sleep(0.05)
            fd = _fs.try_lock_dir(self.root)
            if fd is not None:
                return fd
        raise LakeBusyError(
            f"{self.root}: another commit holds the lake{self._holder_hint()}"
            + (f" and did not finish within {self.lock_wait_s:g} s" if self.lock_wait_s > 0 else "")
            + "; try again when it is done"
        )

    def _holder_hint(self) -> str:
        return _fs.lock_holder_hint(self.root / WRITER_HINT)

    def _recover_locked(self) -> None:
        staging = self.root / STAGING
        if staging.is_dir():
            for intent in sorted(staging.glob(f"*{INTENT_SUFFIX}")):
                _log.warning("%s: finishing a replace a killed writer left", self.root)
                self._roll_forward(intent)
            stale = sorted(staging.iterdir())
            for entry in stale:
                if entry.is_dir() and not entry.is_symlink():
                    shutil.rmtree(entry)
                else:
                    entry.unlink()
            if stale:
                _log.warning(
                    "%s: removed %d unfinished commit(s) from %s", self.root, len(stale), STAGING
                )
                _fs.fsync_dir(staging)
        # Temporary files of atomic writes a dead writer left: in derived tables, and in the
        # folders other writers keep at the lake's top level (e.g. the bag reports, _bags/).
        leftovers = [
            *self.root.glob(f"robot=*/date=*/run=*/{DERIVED_DIR}/.*.tmp"),
            *self.root.glob("_*/.*.tmp"),
        ]
        for tmp in leftovers:
            tmp.unlink()

    def _roll_forward(self, intent_path: Path) -> None:
        """Carry a replace from its intent record to the end; each step is idempotent."""
        try:
            intent = json.loads(intent_path.read_bytes())
            staged = self.root / STAGING / intent["staged"]
            final = self.root / intent["final"]
            old = self.root / intent["old"]
            trash = self.root / STAGING / intent["trash"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise LakeError(f"{intent_path}: unreadable replace intent: {exc}") from exc
        if staged.is_dir():
            if old.is_dir() and not trash.exists():
                _fs.rename(old, trash)
                _fs.fsync_dir(old.parent)
                _fs.fsync_dir(trash.parent)
            _fs.make_dirs(final.parent)
            _fs.rename(staged, final)
            _fs.fsync_dir(final.parent)
            _fs.fsync_dir(staged.parent)
        shutil.rmtree(trash, ignore_errors=True)
        intent_path.unlink()
        _fs.fsync_dir(intent_path.parent)


def compact_log(
    log_dir: Path | str,
    lake: Lake,
    *,
    robot: str,
    run: str | None = None,
    date: str | dt.date | None = None,
    replace: bool = False,
    progress: Callable[[Iterable[Event]], Iterable[Event]] | None = None,
) -> RunInfo:
    """Seal an event log into the lake as one run (``run`` defaults to the log's stream).

    Only a sealed log is compacted: one whose writer has closed it (its lock is free), so the
    run in the lake is the whole stream. Compacting it again after more appends needs
    ``replace=True``; compacting it unchanged is a no-op. ``progress`` wraps the events as
    they are read (the CLI's progress line).
    """
    log_dir = Path(log_dir)
    if _fs.is_locked(log_dir / LOCK_FILE):
        raise LakeError(
            f"event log {log_dir} is being written (its lock is held{_fs.lock_holder_hint(log_dir / LOCK_FILE)}); "
            "close the writer before compacting it"
        )
    events = read_log(log_dir, store=lake.store)
    first = next(events, None)
    if first is None:
        raise LakeError(f"event log {log_dir} is empty; there is nothing to compact")
    run = run or first.stream
    identity = {"first_event_id": first.event_id}
    meta = read_meta(log_dir)
    if meta.run_id is not None:
        identity["run_id"] = meta.run_id
    for other in lake.holding(identity):
        if (other.robot, other.run) != (robot, run):
            raise LakeError(
                f"event log {log_dir} (agent run {meta.run_id or first.stream}) is already in "
                f"the lake as run {other.run!r} of robot {other.robot!r} ({other.path}, from "
                f"{other.source}); adding it again would count its events twice"
            )
    _refuse_runs_holding_events_of(log_dir, meta.id_key(), first.stream, lake, (robot, run))

    def all_events() -> Iterable[Event]:
        yield first
        yield from events

    return lake.commit_events(
        progress(all_events()) if progress else all_events(),
        robot=robot,
        run=run,
        date=date,
        source=f"event log {log_dir.resolve()}",
        replace=replace,
        identity=identity,
    )


def _refuse_runs_holding_events_of(
    log_dir: Path, id_key: str, stream: str, lake: Lake, target: tuple[str, str]
) -> None:
    """An event id is in the lake at most once: refuse a log some of whose events a run of
    unknown run id already holds (the pieces of a recording that started after ``run_started``,
    ingested first). Its events carry the log's own ids, uuid5(run id, seq)."""
    for other in lake.runs():
        if "run_id" in other.identity or (other.robot, other.run) == target:
            continue
        for table in lake.read_tables(other).values():
            if not {"event_id", "seq", "stream"} <= set(table.column_names):
                continue
            for event_id, seq, of in zip(
                table["event_id"].to_pylist(),
                table["seq"].to_pylist(),
                table["stream"].to_pylist(),
                strict=True,
            ):
                if of == stream and event_id == deterministic_event_id(id_key, seq):
                    raise LakeError(
                        f"event log {log_dir} is already partly in the lake: run "
                        f"{other.run!r} of robot {other.robot!r} ({other.path}, from "
                        f"{other.source}) holds its event seq {seq} ({event_id}); adding the log "
                        "would count those events twice. Move that run's folder out of the lake "
                        "first (the log holds every event the recording has)"
                    )


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


def _stage(
    staged: Path,
    tables: Mapping[str, pa.Table],
    manifest: Mapping[str, Any],
    attachments: Mapping[str, bytes],
    store: Store,
) -> None:
    """Write a run's files into its staging folder, each fsync'ed, the manifest last, with
    every file's digest and its own."""
    files: dict[str, FileDigest] = {}
    for event_type, table in tables.items():
        name = f"{event_type}.parquet"
        files[name] = _write_parquet(staged / name, table.sort_by("seq"))
    derived = derive_run(
        tables, robot=manifest["robot"], date=manifest["date"], run=manifest["run"], store=store
    )
    _fs.make_dirs(staged / DERIVED_DIR)
    for spec in derived_tables(store):
        path = spec.path(staged)
        files[_relative(path, staged)] = _write_parquet(path, derived[spec.name])
    _fs.fsync_dir(staged / DERIVED_DIR)
    for name, data in sorted(attachments.items()):
        _fs.write_atomic(staged / name, data)
        files[name] = bytes_digest(data)
    _fs.write_atomic(staged / RUN_FILE, _manifest_bytes(manifest, files))
    _fs.fsync_dir(staged)


def _manifest_bytes(manifest: Mapping[str, Any], files: Mapping[str, FileDigest]) -> bytes:
    doc = {k: v for k, v in manifest.items() if k not in (FILES_KEY, SELF_KEY)}
    doc[FILES_KEY] = {name: files[name].as_json() for name in sorted(files)}
    doc[SELF_KEY] = manifest_digest(doc)
    return _json_bytes(doc)


def _relative(path: Path, run_dir: Path) -> str:
    return path.relative_to(run_dir).as_posix()


def _parquet_files(info: RunInfo) -> list[Path]:
    """The Parquet files readers may read of a run: its event tables, its current derived ones."""
    paths = [info.path / f"{t}.parquet" for t in sorted(info.rows)]
    return paths + [p for d in info.derived if (p := d.path(info.path)).is_file()]


def _owned_files(info: RunInfo) -> list[Path]:
    """Every file a commit of this run wrote that is there now: the Parquet files readers read
    and the attachments (for a run committed before digests, when they are recorded)."""
    attachments = [
        p
        for p in sorted(info.path.glob("_*"))
        if p.is_file() and p.name != RUN_FILE and _ATTACHMENT.fullmatch(p.name)
    ]
    return _parquet_files(info) + attachments


def _record_digests(info: RunInfo) -> RunInfo:
    """Write the digests of the files of a run committed before digests into its manifest."""
    hashed = file_digests(_owned_files(info))
    files = {}
    for path, got in hashed.items():
        if isinstance(got, OSError):
            raise LakeError(f"{path}: cannot read it to record its digest: {got.strerror or got}")
        files[_relative(path, info.path)] = got
    _rewrite_manifest(info, files)
    return _read_run_file(info.path / RUN_FILE, info.derived)


def _rewrite_manifest(info: RunInfo, files: Mapping[str, FileDigest]) -> None:
    """Replace a committed run's manifest (atomically) with the same content and ``files``."""
    doc = json.loads((info.path / RUN_FILE).read_bytes())
    _fs.write_atomic(info.path / RUN_FILE, _manifest_bytes(doc, files))


def _write_derived(
    run_dir: Path, tables: Mapping[str, pa.Table], info: RunInfo, store: Store
) -> None:
    """Add the missing derived tables to a committed run, each atomically (tmp file, rename),
    then record their digests in the manifest if it has digests. A kill between the two leaves a
    file the manifest does not list, which readers treat as missing (see
    :meth:`RunInfo.missing_derived`)."""
    derived = derive_run(tables, robot=info.robot, date=info.date, run=info.run, store=store)
    _fs.make_dirs(run_dir / DERIVED_DIR)
    files = dict(info.files)
    for spec in info.missing_derived():
        final = spec.path(run_dir)
        tmp = final.with_name(f".{final.name}.{uuid.uuid4().hex}.tmp")
        try:
            files[_relative(final, run_dir)] = _write_parquet(tmp, derived[spec.name])
            _fs.rename(tmp, final)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
        # An older version of the same table is dead weight once the current one is in place.
        for stale in final.parent.glob(f"{spec.name}.v*.parquet"):
            if stale != final:
                stale.unlink()
                files.pop(_relative(stale, run_dir), None)
    _fs.fsync_dir(run_dir / DERIVED_DIR)
    if info.files:
        _rewrite_manifest(info, files)


def _write_parquet(path: Path, table: pa.Table) -> FileDigest:
    """Write ``table`` (with page checksums) and return the digest of the bytes meant for disk:
    hashed before they are written, so damage on the way is caught, not vouched for."""
    sink = pa.BufferOutputStream()
    pq.write_table(
        table,
        sink,
        compression="zstd",
        row_group_size=ROW_GROUP_ROWS,
        write_page_checksum=True,
    )
    data = memoryview(sink.getvalue())
    with path.open("wb") as fh:
        fh.write(data)
    _fs.fsync_file(path)
    return bytes_digest(data)


def _read_parquet(path: Path, want: FileDigest | None = None) -> pa.Table:
    """A Parquet file as a table, checked against ``want`` (its recorded digest) when given and
    against its page checksums when it has them."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise LakeError(f"{path}: cannot read it: {exc.strerror or exc}") from exc
    if want is not None:
        problem = mismatch(path.name, want, bytes_digest(data))
        if problem is not None:
            raise LakeError(f"{path}: damaged Parquet file: {problem}")
    # ParquetFile, not read_table: the latter would add the hive partition columns.
    try:
        return pq.ParquetFile(pa.BufferReader(data), page_checksum_verification=True).read()
    except (OSError, pa.ArrowException) as exc:
        raise LakeError(f"{path}: damaged Parquet file: {exc}") from exc


def _decode_problem(path: Path) -> str | None:
    """Why ``path`` does not decode in full as Parquet (page checksums checked), or None."""
    problem = parquet_problem(path)
    if problem is not None:
        return problem
    try:
        pq.ParquetFile(path, page_checksum_verification=True).read()
    except (OSError, pa.ArrowException) as exc:
        return f"{path.name} does not decode: {exc}"
    return None


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


def deep_check(run: RunInfo, *, digests_checked: bool = False) -> str | None:
    """Why a run's files are not the ones committed (digests compared, for a run that has them,
    unless ``digests_checked``: a ``scan(check_digests=True)`` just did) or its Parquet files
    cannot be opened (footers parsed), or None."""
    problems = [] if digests_checked else _damage(run)
    if problems:
        return "; ".join(problems)
    for path in sorted(run.path.glob("*.parquet")) + sorted(
        (run.path / DERIVED_DIR).glob("*.parquet")
    ):
        try:
            pq.read_metadata(path)
        except (OSError, pa.ArrowException) as exc:
            return f"{path.name}: {exc}"
    return None


def _damage(info: RunInfo) -> list[str]:
    """What is damaged in a committed run with digests (every byte read), else nothing known."""
    if not info.files:
        return []
    return _run_problems(info, file_digests(info.path / name for name in info.files))


def _run_problems(info: RunInfo, hashed: Mapping[Path, FileDigest | OSError] | None) -> list[str]:
    """Why readers must leave a run out: checks of :meth:`Lake.scan`; the files' digests are
    compared when ``hashed`` (every listed file's digest) is given, else only their sizes."""
    problems = []
    where = (f"robot={info.robot}", f"date={info.date}", f"run={info.run}")
    if (info.path.parent.parent.name, info.path.parent.name, info.path.name) != where:
        problems.append(
            f"its manifest describes {'/'.join(where)}, not this folder (moved or swapped)"
        )
    listed = {f"{t}.parquet" for t in info.rows}
    for extra in sorted(p.name for p in info.path.glob("*.parquet")):
        if extra not in listed:
            problems.append(f"{extra} is not in the run's manifest (added after the commit)")
    for name in sorted(listed - set(info.files) if info.files else ()):
        problems.append(f"{name} has no digest in the manifest")
    reported = set()  # files whose ends are wrong: their size and digest would say it again
    for path in _parquet_files(info):
        problem = parquet_problem(path)
        if problem is not None:
            problems.append(problem)
            reported.add(_relative(path, info.path))
    for name, want in sorted(info.files.items()):
        if name in reported:
            continue
        got: FileDigest | OSError | None
        if hashed is not None:
            got = hashed[info.path / name]
        else:
            try:
                got = FileDigest(os.stat(info.path / name).st_size, want.digest)
            except OSError as exc:
                got = exc
        if isinstance(got, FileNotFoundError) and name.startswith(f"{DERIVED_DIR}/"):
            continue  # a derived table is a function of the events: readers compute it
        problem = mismatch(name, want, got)
        if problem is not None:
            problems.append(problem)
    return problems


def _digest(tables: Mapping[str, pa.Table]) -> str:
    h = hashlib.sha256()
    for event_type, table in tables.items():
        h.update(event_type.encode() + b"\0")
        sink = pa.BufferOutputStream()
        with pa.ipc.new_stream(sink, table.schema) as writer:
            writer.write_table(table)
        h.update(sink.getvalue().to_pybytes())
    return "sha256:" + h.hexdigest()


def _json_bytes(doc: Mapping[str, Any]) -> bytes:
    return json.dumps(doc, indent=1, sort_keys=True, ensure_ascii=False).encode() + b"\n"


def _read_run_file(path: Path, derived: tuple[DerivedTable, ...]) -> RunInfo:
    try:
        doc = json.loads(path.read_bytes())
    except (OSError, ValueError) as exc:
        raise LakeError(f"{path}: cannot read the run manifest: {exc}") from exc
    if not isinstance(doc, dict) or doc.get("format") != LAKE_FORMAT:
        raise LakeError(f"{path}: not a {LAKE_FORMAT} run manifest")
    if SELF_KEY in doc and doc[SELF_KEY] != manifest_digest(doc):
        raise LakeError(
            f"{path}: the run manifest fails its digest: its bytes are not the ones committed"
        )
    try:
        return RunInfo(
            robot=str(doc["robot"]),
            date=str(doc["date"]),
            run=str(doc["run"]),
            path=path.parent,
            rows={str(t): int(n) for t, n in dict(doc["rows"]).items()},
            digest=str(doc["digest"]),
            source=str(doc["source"]),
            identity={str(k): str(v) for k, v in dict(doc.get("identity") or {}).items()},
            files=parse_files(doc[FILES_KEY]) if FILES_KEY in doc else {},
            derived=derived,
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise LakeError(f"{path}: run manifest lacks or mistypes {exc}") from exc


def _check_name(what: str, value: str) -> None:
    if not (isinstance(value, str) and _NAME.fullmatch(value)):
        raise LakeError(
            f"{what} name {value!r} must start with a letter or digit and hold only letters, "
            "digits, '.', '_' and '-' (it becomes a directory name)"
        )


def _check_date(value: str | dt.date) -> str:
    try:
        day = value if isinstance(value, dt.date) else dt.date.fromisoformat(value)
    except (TypeError, ValueError):
        raise LakeError(f"date {value!r} is not an ISO date (YYYY-MM-DD)") from None
    return day.isoformat()
