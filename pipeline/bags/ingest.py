"""``objsearch ingest``: bags into the lake, one atomic commit per bag, in parallel processes.

A bag is one task: read it (:func:`~objsearch.pipeline.bags.read.read_bag`), commit its events
(:class:`~objsearch.pipeline.bags.lake.LakeWriter`). Tasks share nothing but the lake, whose
commits are atomic per bag, so ``--workers N`` runs them in N processes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

from objsearch.pipeline.bags.errors import BagError
from objsearch.pipeline.bags.lake import ParquetLake
from objsearch.pipeline.bags.read import BagReport, bag_identity, read_bag
from objsearch.pipeline.bags.topics import TopicMap


@dataclass(frozen=True, slots=True)
class IngestResult:
    path: str
    report: BagReport | None  # None when the bag was already in the lake (not read again)
    committed: int  # events written by this run (0 for a no-op)
    already: bool
    error: str | None = None


def ingest_one(
    bag: Path, lake_dir: Path, topic_map: TopicMap, robot: str, progress: bool = False
) -> IngestResult:
    """Read one bag and commit it; an error is returned, not raised, so a fleet run goes on."""
    lake = ParquetLake(lake_dir)
    try:
        bag_id, _ = bag_identity(bag) if bag.exists() else ("", 0)
        if not bag_id:
            raise BagError(f"no bag at {bag}: no such file or directory")
        if lake.has_bag(bag_id):
            return IngestResult(str(bag), None, 0, already=True)
        contents = read_bag(bag, topic_map, progress=progress)
        commit = lake.commit_bag(
            contents.report.bag_id,
            contents.events,
            robot=robot,
            start_ns=contents.report.start_ns,
            report=dataclasses.asdict(contents.report),
        )
    except Exception as exc:  # noqa: BLE001 - one bad bag must not stop the others
        return IngestResult(str(bag), None, 0, already=False, error=str(exc) or repr(exc))
    return IngestResult(
        str(bag), contents.report, commit.events if commit.new else 0, already=not commit.new
    )


def ingest(
    bags: Sequence[Path],
    lake_dir: Path,
    *,
    topic_map: TopicMap | None = None,
    robot: str = "robot",
    workers: int = 1,
    progress: bool = False,
    on_result: Callable[[IngestResult], None] | None = None,
) -> list[IngestResult]:
    """Ingest every bag (duplicates by path once); results in the order of ``bags``."""
    topic_map = topic_map or TopicMap()
    unique = list(dict.fromkeys(Path(b) for b in bags))
    results: dict[Path, IngestResult] = {}
    if workers <= 1 or len(unique) <= 1:
        for bag in unique:
            results[bag] = ingest_one(bag, lake_dir, topic_map, robot, progress)
            if on_result:
                on_result(results[bag])
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = {
                pool.submit(ingest_one, bag, lake_dir, topic_map, robot, False): bag
                for bag in unique
            }
            for fut in as_completed(futures):
                results[futures[fut]] = fut.result()
                if on_result:
                    on_result(results[futures[fut]])
    return [results[b] for b in unique]
