"""Where ingested bags go: the event lake (:mod:`objsearch.events.lake`), one run per bag.

Ingest needs three things of the lake, behind the :class:`LakeWriter` seam: which bags are in it
already (``known_runs``, handed to workers so they skip those bags without reading them; and
``has_bag``), and to commit a bag's tables whole (``commit_bag``). :class:`BagLake` does both with the
event store's lake, so bags and compacted agent logs share one layout, one set of typed Parquet
tables and one set of DuckDB views::

    LAKE/robot=<robot>/date=<YYYY-MM-DD>/run=bag-<bag id, 16 hex>/<event type>.parquet, _run.json
    LAKE/robot=<robot>/date=<YYYY-MM-DD>/run=bag-<bag id, 16 hex>/_ingest.json   the report
    LAKE/_bags/<bag id>.json          a copy of the report, found by bag id

The lake commits a run atomically (staging folder, fsync, rename), so a reader sees all of a bag or
none of it; the run name carries the bag id, so committing a bag twice is a no-op. The ingest
report (what was read, skipped, salvaged) is committed inside the run, so a run never lacks it;
its copy in ``_bags/`` is written after the run, under the same lake lock, and restored from the
run by any later ingest of that bag if a crash came between the two.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import pyarrow as pa

from objsearch.events import Event, EventStoreError, _fs
from objsearch.events.lake import Lake
from objsearch.pipeline.bags.errors import BagCommitError

MANIFESTS = "_bags"
RUN_PREFIX = "bag-"
RUN_REPORT = "_ingest.json"  # the report's copy inside the run, committed with it

_log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Commit:
    bag_id: str
    path: Path | None  # the run's folder
    events: int
    new: bool  # False when the bag was already in the lake


class LakeWriter(Protocol):
    def known_runs(self) -> frozenset[str]: ...

    def has_bag(self, bag_id: str) -> bool: ...

    def restore_report(self, bag_id: str) -> bool: ...

    def commit_bag(
        self,
        bag_id: str,
        tables: Mapping[str, pa.Table],
        *,
        robot: str,
        start_ns: int | None,
        report: Mapping[str, Any],
    ) -> Commit: ...


def run_name(bag_id: str) -> str:
    return RUN_PREFIX + bag_id[:16]


class BagLake:
    """:class:`LakeWriter` over the event store's :class:`~objsearch.events.lake.Lake`."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.lake = Lake(self.root)

    def _runs(self, bag_id: str) -> list[Path]:
        return sorted(self.root.glob(f"robot=*/date=*/run={run_name(bag_id)}/_run.json"))

    def known_runs(self) -> frozenset[str]:
        """The run names (:func:`run_name`) of every bag in the lake: one directory listing."""
        return frozenset(
            p.parent.name.removeprefix("run=")
            for p in self.root.glob(f"robot=*/date=*/run={RUN_PREFIX}*/_run.json")
        )

    def has_bag(self, bag_id: str) -> bool:
        return bool(self._runs(bag_id))

    def commit_bag(
        self,
        bag_id: str,
        tables: Mapping[str, pa.Table],
        *,
        robot: str,
        start_ns: int | None,
        report: Mapping[str, Any],
    ) -> Commit:
        """Commit a bag's tables (one per event type, :func:`~objsearch.events.arrow.events_to_tables`)
        with its report, under the lake's lock."""
        events = sum(t.num_rows for t in tables.values())
        date = dt.datetime.fromtimestamp((start_ns or 0) / 1e9, dt.UTC).date()
        run = run_name(bag_id)
        where = f"robot={robot}/date={date.isoformat()}/run={run}"
        doc = {"bag_id": bag_id, "run": where, "events": events, "report": report}
        data = json.dumps(doc, indent=1, sort_keys=True, default=str).encode() + b"\n"
        try:
            with self.lake.locked():
                if self.has_bag(bag_id):
                    self.restore_report(bag_id)
                    return Commit(bag_id, self._runs(bag_id)[0].parent, events, new=False)
                info = self.lake.commit_tables(
                    tables,
                    robot=robot,
                    run=run,
                    date=date,
                    source=f"bag:{bag_id}",
                    attachments={RUN_REPORT: data},
                )
                self._write_report(bag_id, data)
        except (OSError, EventStoreError) as exc:
            raise BagCommitError(
                f"committing bag {bag_id[:16]} to {self.root} failed: {exc}"
            ) from exc
        return Commit(bag_id, info.path, events, new=True)

    def restore_report(self, bag_id: str) -> bool:
        """Write ``_bags/<bag id>.json`` from the run's copy if a crash left it out; returns
        whether it did."""
        runs = self._runs(bag_id)
        report = self.root / MANIFESTS / f"{bag_id}.json"
        if not runs or report.exists() or not (runs[0].parent / RUN_REPORT).is_file():
            return False
        try:
            with self.lake.locked():
                if report.exists():
                    return False
                self._write_report(bag_id, (runs[0].parent / RUN_REPORT).read_bytes())
        except (OSError, EventStoreError) as exc:
            raise BagCommitError(
                f"restoring the report of bag {bag_id[:16]} failed: {exc}"
            ) from exc
        _log.warning(
            "%s: restored the missing report of bag %s from its run", self.root, bag_id[:16]
        )
        return True

    def _write_report(self, bag_id: str, data: bytes) -> None:
        _fs.make_dirs(self.root / MANIFESTS)
        _fs.write_atomic(self.root / MANIFESTS / f"{bag_id}.json", data)

    def events(self) -> Iterator[Event]:
        """Every event of every ingested bag (tests and small lakes; analysts use DuckDB)."""
        for info in self.lake.runs():
            if info.run.startswith(RUN_PREFIX):
                yield from self.lake.read_events(info)
