"""The per-run-folder lake (``objsearch.lake/1``), read only to migrate it into the fleet lake.

Lakes written before the fleet lake became the default kept a folder a run::

    LAKE/robot=<robot>/date=<YYYY-MM-DD>/run=<run>/<event_type>.parquet
    LAKE/robot=<robot>/date=<YYYY-MM-DD>/run=<run>/_run.json      what the run holds, with
                                                                 every file's size and SHA-256
    LAKE/robot=<robot>/date=<YYYY-MM-DD>/run=<run>/_derived/…    derived tables (recomputed)
    LAKE/robot=<robot>/date=<YYYY-MM-DD>/run=<run>/_ingest.json  a bag run's ingest record
    LAKE/_bags/<bag id>.json                                     each bag's report (a copy)

This version writes no such lake and queries none: every command but ``objsearch lake upgrade``
refuses one (:func:`objsearch.events.lake.open_lake`, with one message naming the migration
command), and :func:`migrate` copies its healthy runs into the fleet lake
(:class:`~objsearch.events.lake.fleet.TableLake`). A run whose manifest is unreadable, fails its
own digest or names another folder, or one of whose files is missing, cut, of another size or
fails its SHA-256, is not copied: it is named and left in place. The reports of bags that made
no run are copied into the bag pipeline's ledger in the fleet lake (:class:`BagLedger`), so it
still accounts for every bag.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final, Protocol

import pyarrow as pa
import pyarrow.parquet as pq

from ..derived import DERIVED_DIR
from .common import LakeError, parquet_problem
from .digests import table_digest
from .fleet import TableLake
from .folder_digest import (
    FILES_KEY,
    SELF_KEY,
    FileDigest,
    bytes_digest,
    file_digests,
    manifest_digest,
    mismatch,
    parse_files,
)
from .schema import TableRun, run_parts
from .storage import _token

LAKE_FORMAT: Final = "objsearch.lake/1"
RUN_FILE: Final = "_run.json"
#: Where the old writer staged runs and replaces; a lake killed mid-commit still has one.
STAGING: Final = ".staging"
#: Where ingest kept a copy of every bag's report (a bag that made no run: only there).
BAG_RECORDS: Final = "_bags"
#: A bag run's ingest record (its pieces' reports), committed in the run's folder.
INGEST_RECORD: Final = "_ingest.json"


@dataclass(frozen=True, slots=True)
class DamagedRun:
    """A run folder the migration leaves in place: its manifest or one of its files is not whole."""

    path: Path
    reason: str


@dataclass(frozen=True, slots=True)
class RunInfo:
    """One run of a folder lake: where it is and what its ``_run.json`` says it holds."""

    robot: str
    date: str
    run: str
    path: Path
    rows: Mapping[str, int]  # event type → rows
    source: str
    identity: Mapping[str, str] = field(default_factory=dict)
    #: Size and SHA-256 of every file its commit wrote (empty: committed before digests).
    files: Mapping[str, FileDigest] = field(default_factory=dict)


def left_run_folders(root: Path | str) -> list[Path]:
    """The run folders of the old format a fleet lake's folder still holds (what ``lake
    upgrade`` left in place: damaged, or a run the table held already)."""
    return sorted(Path(root).glob("robot=*/date=*/run=*"))


def is_folder_lake(root: Path | str) -> bool:
    """Whether ``root`` is a local folder holding a per-run-folder lake (a ``robot=…`` folder,
    or the staging folder its writer left)."""
    if "://" in str(root):
        return False
    path = Path(root)
    if not path.is_dir():
        return False
    return (path / STAGING).is_dir() or any(p.is_dir() for p in path.glob("robot=*"))


class BagLedger(Protocol):
    """Where the fleet lake keeps the ingest records of bags that made no run (the bag
    pipeline's ledger, :class:`objsearch.pipeline.bags.ledger.BagLedger`): what the migration
    copies the folder lake's ``_bags/`` into."""

    def records(self) -> Mapping[str, str]:
        """Bag id → its latest record (JSON text)."""
        ...

    def record(self, bag_id: str, robot: str | None, doc: str) -> None:
        """Keep ``doc`` as bag ``bag_id``'s record."""
        ...


class FolderLake:
    """A per-run-folder lake, read-only: its runs, checked, and their event tables."""

    def __init__(self, root: Path | str) -> None:
        self.root = Path(root)

    def scan(
        self, progress: Callable[[list[Path]], Iterable[Path]] | None = None
    ) -> tuple[list[RunInfo], list[DamagedRun]]:
        """The runs whose every byte is the one committed, and the run folders that are not.

        Every file a manifest lists is hashed and compared with its SHA-256; a run committed
        before digests gets its Parquet ends checked here and its pages when it is read."""
        infos: list[RunInfo] = []
        damaged: list[DamagedRun] = []
        for folder in sorted(self.root.glob("robot=*/date=*/run=*")):
            if not folder.is_dir():
                continue
            try:
                infos.append(_read_run_file(folder / RUN_FILE))
            except LakeError as exc:
                damaged.append(DamagedRun(folder, str(exc)))
        hashed = file_digests((r.path / name for r in infos for name in r.files), progress)
        runs: list[RunInfo] = []
        for info in infos:
            problems = _run_problems(info, hashed)
            if problems:
                damaged.append(DamagedRun(info.path, "; ".join(problems)))
            else:
                runs.append(info)
        runs.sort(key=lambda r: (r.robot, r.date, r.run))
        damaged.sort(key=lambda d: d.path)
        return runs, damaged

    def read_tables(self, run: RunInfo) -> dict[str, pa.Table]:
        """The event tables of one run as stored, checked against their recorded digests and
        their page checksums; raises :class:`LakeError` naming a damaged file."""
        return {
            event_type: _read_parquet(
                run.path / f"{event_type}.parquet", run.files.get(f"{event_type}.parquet")
            )
            for event_type in sorted(run.rows)
        }


@dataclass(frozen=True, slots=True)
class Migration:
    """What :func:`migrate` did with each run folder."""

    copied: list[Path]  # now in the fleet table
    already: list[Path]  # a run of that robot and name was in the table: not copied
    damaged: list[DamagedRun]  # not copied, left in place
    #: Ingest records of bags that made no run (``_bags/<bag id>.json``) copied into the table.
    bag_records: int = 0


def migrate(
    old_root: Path | str,
    lake: TableLake,
    *,
    bags: BagLedger,
    batch: int = 64,
    progress: Callable[[list[RunInfo]], Iterable[RunInfo]] | None = None,
) -> Migration:
    """Copy every healthy run of the per-run-folder lake at ``old_root`` into the fleet lake,
    ``batch`` runs a transaction; a run whose robot and name the table holds already is not
    copied. A damaged run (see :meth:`FolderLake.scan`; also one whose pages fail their
    checksums as it is read) is not copied either. Nothing in ``old_root`` is changed.
    ``progress`` wraps the runs as they are copied (the CLI's progress line); the records of bags
    that made no run go to ``bags``."""
    old = FolderLake(old_root)
    healthy, damaged = old.scan()
    lake.create()
    known = {(r.robot, r.run) for r in lake.runs()}
    pending: list[tuple[TableRun, dict[str, pa.Table]]] = []
    copied: list[Path] = []
    already: list[Path] = []
    in_runs: set[str] = set()  # the bags the copied runs' ingest records hold
    for info in progress(healthy) if progress else healthy:
        if (info.robot, info.run) in known:
            already.append(info.path)
            continue
        try:
            tables = old.read_tables(info)
        except LakeError as exc:
            damaged.append(DamagedRun(info.path, str(exc)))
            continue
        attachments = {
            p.name: p.read_text(encoding="utf-8")
            for p in sorted(info.path.glob("_*"))
            if p.is_file() and p.name != RUN_FILE
        }
        run = TableRun(
            robot=info.robot,
            date=info.date,
            run=info.run,
            commit=_token(),
            rows=dict(info.rows),
            digest=table_digest(tables),  # the fleet lake's digest (the old one hashed differently)
            source=info.source,
            identity=dict(info.identity),
            attachments=attachments,
        )
        pending.append((run, run_parts(tables, run, lake.store)))
        copied.append(info.path)
        in_runs |= _pieces(attachments.get(INGEST_RECORD))
        if len(pending) >= batch:
            lake.commit_many(pending)
            pending = []
    lake.commit_many(pending)
    recorded = _copy_bag_records(old.root / BAG_RECORDS, bags, in_runs)
    return Migration(copied, already, sorted(damaged, key=lambda d: d.path), recorded)


def _copy_bag_records(folder: Path, bags: BagLedger, in_runs: set[str]) -> int:
    """Copy the ingest records of bags no run's ``_ingest.json`` holds (a bag that made no run,
    one whose events the lake held already) into the table's bag rows, so the lake still
    accounts for every bag it was given; returns how many. Records the table has are skipped."""
    if not folder.is_dir():
        return 0
    have = set(bags.records())
    count = 0
    for path in sorted(folder.glob("*.json")):
        bag_id = path.stem
        if bag_id in in_runs or bag_id in have:
            continue
        text = path.read_text(encoding="utf-8")
        try:
            doc = json.loads(text)
        except ValueError:
            doc = {}
        robot = doc.get("robot") if isinstance(doc, dict) else None
        bags.record(bag_id, str(robot) if robot else None, text)
        count += 1
    return count


def _pieces(ingest_record: str | None) -> set[str]:
    """The bag ids a bag run's ``_ingest.json`` records."""
    if ingest_record is None:
        return set()
    try:
        doc = json.loads(ingest_record)
    except ValueError:
        return set()
    if not isinstance(doc, dict):
        return set()
    pieces = doc.get("pieces")
    if isinstance(pieces, dict):
        return {str(k) for k in pieces}
    return {str(doc["bag_id"])} if "bag_id" in doc else set()


def _read_run_file(path: Path) -> RunInfo:
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
            source=str(doc["source"]),
            identity={str(k): str(v) for k, v in dict(doc.get("identity") or {}).items()},
            files=parse_files(doc[FILES_KEY]) if FILES_KEY in doc else {},
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise LakeError(f"{path}: run manifest lacks or mistypes {exc}") from exc


def _run_problems(info: RunInfo, hashed: Mapping[Path, FileDigest | OSError]) -> list[str]:
    """Why the migration must leave a run behind (every listed file hashed in ``hashed``)."""
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
    for name in sorted(listed):
        problem = parquet_problem(info.path / name)
        if problem is not None:
            problems.append(problem)
            reported.add(name)
    for name, want in sorted(info.files.items()):
        if name in reported:
            continue
        got = hashed[info.path / name]
        if isinstance(got, FileNotFoundError) and name.startswith(f"{DERIVED_DIR}/"):
            continue  # derived tables are recomputed from the events, not copied
        problem = mismatch(name, want, got)
        if problem is not None:
            problems.append(problem)
    return problems


def _read_parquet(path: Path, want: FileDigest | None) -> pa.Table:
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


__all__ = [
    "LAKE_FORMAT",
    "BagLedger",
    "DamagedRun",
    "FolderLake",
    "Migration",
    "RunInfo",
    "is_folder_lake",
    "left_run_folders",
    "migrate",
]
