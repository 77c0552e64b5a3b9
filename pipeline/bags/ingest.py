"""``objsearch ingest``: bags into the lake, one atomic commit per bag, on a choice of engines.

A bag is one task, :func:`convert_bag`: hash it, read it (:func:`~objsearch.pipeline.bags.read.read_bag`)
and turn its events into the lake's typed Arrow tables. Tasks run wherever the
:class:`~objsearch.pipeline.bags.engines.Engine` puts them (this process, ``--workers N`` local
processes, a Ray cluster) and write nothing. The caller — the driver — commits each result as it
arrives (:class:`~objsearch.pipeline.bags.lake.LakeWriter`), so the lake needs to be reachable
from one machine only, and atomicity stays with the lake's rename on that machine.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pyarrow as pa

from objsearch.events.errors import ObjsearchError
from objsearch.pipeline.bags.engines import Engine, InlineEngine, ProcessEngine, TaskFailed
from objsearch.pipeline.bags.errors import BagError
from objsearch.pipeline.bags.identity import bag_identity
from objsearch.pipeline.bags.lake import LakeWriter, Piece, open_bag_lake
from objsearch.pipeline.bags.read import read_bag
from objsearch.pipeline.bags.report import BagReport
from objsearch.pipeline.bags.session import FirstEvent, converter_key, first_event, run_id_of
from objsearch.ros.topics import TopicMap


@dataclass(frozen=True, slots=True)
class IngestResult:
    path: str
    report: BagReport | None  # None when the bag was already in the lake (not read again)
    committed: int  # events written by this run (0 for a no-op)
    already: bool
    error: str | None = None
    note: str = ""  # where the bag went when that is news (merged into a session, a duplicate)


@dataclass(frozen=True, slots=True)
class BagTask:
    """What a worker needs for one bag; small and picklable (it travels to Ray workers)."""

    path: Path
    topic_map: TopicMap
    #: Bag id → converter key of the bags already in the lake: a bag listed with this task's
    #: key is not read again; one read with another topic map or converter version is.
    known: Mapping[str, str] = field(default_factory=dict)
    progress: bool = False
    reingest: bool = False  # read it again even if the lake has it with this key
    identity: tuple[str, int] | None = None  # the bag's (bag_identity), when hashed already


@dataclass(frozen=True, slots=True)
class Converted:
    """A task's answer: the bag's tables and report, or why there are none."""

    path: str
    bag_id: str
    report: BagReport | None
    tables: Mapping[str, pa.Table] = field(default_factory=dict)
    already: bool = False
    error: str | None = None
    converter: str = ""
    run_id: str | None = None
    first: FirstEvent | None = None
    reingest: bool = False


def convert_bag(task: BagTask) -> Converted:
    """Read one bag into tables. Writes nothing; an error is returned, not raised."""
    path = str(task.path)
    try:
        if not task.path.exists():
            raise BagError(f"no bag at {task.path}: no such file or directory")
        identity = task.identity or bag_identity(task.path)
        key = converter_key(task.topic_map)
        if task.known.get(identity[0]) == key and not task.reingest:
            return Converted(path, identity[0], None, already=True)
        contents = read_bag(task.path, task.topic_map, progress=task.progress, identity=identity)
        return Converted(
            path,
            identity[0],
            contents.report,
            contents.tables(),
            converter=key,
            run_id=run_id_of(contents.agent, ()),
            first=first_event(contents.agent),
            reingest=task.reingest,
        )
    except Exception as exc:  # boundary: one bag's task fails, the other bags go on
        return Converted(path, "", None, error=str(exc) or repr(exc))


def _identity(bag: Path) -> tuple[str, int] | None:
    """The bag's identity, or None if it cannot be read (its task says why)."""
    try:
        return bag_identity(bag)
    except OSError:  # gone, unreadable, or not a folder: the task's reader says which
        return None


def commit_converted(lake: LakeWriter, converted: Converted, robot: str) -> IngestResult:
    """The driver's half: commit one task's tables atomically; an error is returned, not raised."""
    if converted.already:
        return IngestResult(converted.path, None, 0, already=True)
    if converted.error is not None or converted.report is None:
        return IngestResult(converted.path, None, 0, converted.already, converted.error)
    report = converted.report
    if report.events == 0:
        # A piece with nothing the lake keeps (e.g. a split's last seconds with no converted
        # topic) makes no run: an empty run would only show up as a session of its own. Its
        # report is kept all the same: what the bag claimed and lost stays accounted for.
        try:
            lake.record_without_run(report.bag_id, dataclasses.asdict(report))
        except _lake_errors() as exc:
            return IngestResult(converted.path, None, 0, already=False, error=str(exc) or repr(exc))
        return IngestResult(
            converted.path,
            report,
            0,
            already=False,
            note="no events to keep; nothing committed (no run is made from an empty bag)",
        )
    piece = Piece(
        report.bag_id,
        converted.tables,
        dataclasses.asdict(report),
        report.start_ns,
        report.end_ns,
        converted.converter,
        converted.run_id,
        converted.first,
        converted.reingest,
    )
    try:
        commit = lake.commit_piece(piece, robot=robot)
    except _lake_errors() as exc:
        return IngestResult(converted.path, None, 0, already=False, error=str(exc) or repr(exc))
    return IngestResult(
        converted.path, report, commit.events, already=not commit.new, note=commit.note
    )


def _lake_errors() -> tuple[type[Exception], ...]:
    """What a failed write to the lake raises: the lake's own errors (most of the rest wrapped in
    :class:`BagCommitError`), and what the file system, Arrow and Delta raise under them."""
    from deltalake.exceptions import DeltaError

    return (ObjsearchError, OSError, pa.ArrowException, DeltaError)


def ingest(
    bags: Sequence[Path],
    lake_dir: Path | str,
    *,
    topic_map: TopicMap | None = None,
    robot: str = "robot",
    workers: int = 1,
    engine: Engine | None = None,
    progress: bool = False,
    reingest: bool = False,
    on_result: Callable[[IngestResult], None] | None = None,
) -> list[IngestResult]:
    """Ingest every bag (duplicates by path once); results in the order of ``bags``.

    ``engine`` defaults to this process for one worker and ``workers`` local processes otherwise.
    A bag the lake holds is read again when its topic map or the converter version changed, or
    with ``reingest``; its rows in its session's run are replaced.
    """
    topic_map = topic_map or TopicMap()
    unique = list(dict.fromkeys(Path(b) for b in bags))
    if engine is None:
        engine = InlineEngine() if workers <= 1 or len(unique) <= 1 else ProcessEngine(workers)
    lake = open_bag_lake(lake_dir)  # a folder, or the fleet lake (a bucket, a Delta table)
    identities: dict[Path, tuple[str, int]] = {}
    known: Mapping[str, str] | None = None
    if lake.asks_by_bag_id:
        # The fleet lake answers per bag from its log (no row read): hashed here, once.
        identities = {b: ident for b in unique if (ident := _identity(b)) is not None}
        bag_ids = [bag_id for bag_id, _ in identities.values()]
        known = lake.pieces_known(bag_ids, converter_key(topic_map))
    if known is None:
        known = lake.known_pieces()
    show = progress and engine.in_process
    tasks = [BagTask(bag, topic_map, known, show, reingest, identities.get(bag)) for bag in unique]
    results: dict[int, IngestResult] = {}
    for i, outcome in engine.run(convert_bag, tasks):
        if isinstance(outcome, TaskFailed):
            results[i] = IngestResult(str(unique[i]), None, 0, already=False, error=outcome.message)
        else:
            results[i] = commit_converted(lake, outcome, robot)
        if on_result:
            on_result(results[i])
    return [results[i] for i in range(len(unique))]
