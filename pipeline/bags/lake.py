"""Where ingested bags go: the event lake (:mod:`objsearch.events.lake`), one run per bag.

Ingest needs three things of the lake, behind the :class:`LakeWriter` seam: which bags are in it
already (``known_runs``, handed to workers so they skip those bags without reading them; and
``has_bag``), and to commit a bag's tables whole (``commit_bag``). :class:`BagLake` does both with the
event store's lake, so bags and compacted agent logs share one layout, one set of typed Parquet
tables and one set of DuckDB views::

    LAKE/robot=<robot>/date=<YYYY-MM-DD>/run=bag-<bag id, 16 hex>/<event type>.parquet, _run.json
    LAKE/_bags/<bag id>.json          the ingest report (what was read, skipped, salvaged)

The lake commits a run atomically (staging folder, fsync, rename), so a reader sees all of a bag or
none of it; the run name carries the bag id, so committing a bag twice is a no-op.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import uuid
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import pyarrow as pa

from objsearch.events import Event, EventStoreError
from objsearch.events.lake import Lake
from objsearch.pipeline.bags.errors import LakeError

MANIFESTS = "_bags"
RUN_PREFIX = "bag-"


@dataclass(frozen=True, slots=True)
class Commit:
    bag_id: str
    path: Path | None  # the run's folder
    events: int
    new: bool  # False when the bag was already in the lake


class LakeWriter(Protocol):
    def known_runs(self) -> frozenset[str]: ...

    def has_bag(self, bag_id: str) -> bool: ...

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
        """Commit a bag's tables (one per event type, :func:`~objsearch.events.arrow.events_to_tables`)."""
        events = sum(t.num_rows for t in tables.values())
        if self.has_bag(bag_id):
            return Commit(bag_id, self._runs(bag_id)[0].parent, events, new=False)
        date = dt.datetime.fromtimestamp((start_ns or 0) / 1e9, dt.UTC).date()
        try:
            info = self.lake.commit_tables(
                tables, robot=robot, run=run_name(bag_id), date=date, source=f"bag:{bag_id}"
            )
        except (OSError, EventStoreError) as exc:
            raise LakeError(f"committing bag {bag_id[:16]} to {self.root} failed: {exc}") from exc
        self._write_manifest(bag_id, info.path, events, report)
        return Commit(bag_id, info.path, events, new=True)

    def _write_manifest(
        self, bag_id: str, run: Path, events: int, report: Mapping[str, Any]
    ) -> None:
        path = self.root / MANIFESTS / f"{bag_id}.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        doc = {
            "bag_id": bag_id,
            "run": str(run.relative_to(self.root)),
            "events": events,
            "report": report,
        }
        tmp = path.with_suffix(f".{uuid.uuid4().hex}.tmp")
        tmp.write_text(json.dumps(doc, indent=1, sort_keys=True, default=str), encoding="utf-8")
        os.replace(tmp, path)

    def events(self) -> Iterator[Event]:
        """Every event of every ingested bag (tests and small lakes; analysts use DuckDB)."""
        for info in self.lake.runs():
            if info.run.startswith(RUN_PREFIX):
                yield from self.lake.read_events(info)
