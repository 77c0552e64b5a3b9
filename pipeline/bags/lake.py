"""Where ingested bags go: a Parquet event lake, behind the :class:`LakeWriter` seam.

This is a stand-in until the event store's lake (issue 4) lands: ingest only needs
``has_bag`` and ``commit_bag``, so swapping the implementation changes nothing else.

Layout (Hive partitions, readable by DuckDB's ``read_parquet(..., hive_partitioning=true)``)::

    LAKE/robot=<robot>/date=<YYYY-MM-DD>/run=<run>/bag-<bag id>.parquet
    LAKE/_bags/<bag id>.json          what was committed, and the ingest report

A bag is committed as one Parquet file written beside the lake, fsync'ed and renamed into place:
a reader sees all of a bag or none of it, and a crash leaves at most a file in ``_staging/``.
The file name carries the bag id, so committing a bag twice is a no-op.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import re
import uuid
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from objsearch.events import Event
from objsearch.pipeline.bags.errors import LakeError

STAGING = "_staging"
MANIFESTS = "_bags"
COLUMNS = (
    "event_id",
    "stream",
    "seq",
    "time_ns",
    "recorded_at_ns",
    "type",
    "version",
    "task_id",
    "payload",
    "bag_id",
)


@dataclass(frozen=True, slots=True)
class Commit:
    bag_id: str
    path: Path | None  # None when the bag held nothing to store
    events: int
    new: bool  # False when the bag was already in the lake


class LakeWriter(Protocol):
    def has_bag(self, bag_id: str) -> bool: ...

    def commit_bag(
        self,
        bag_id: str,
        events: Sequence[Event],
        *,
        robot: str,
        start_ns: int | None,
        report: Mapping[str, Any],
    ) -> Commit: ...


_SAFE = re.compile(r"[^A-Za-z0-9._-]+")


def _part(value: str) -> str:
    return _SAFE.sub("_", value) or "_"


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class ParquetLake:
    def __init__(self, root: Path) -> None:
        self.root = root

    def _manifest(self, bag_id: str) -> Path:
        return self.root / MANIFESTS / f"{bag_id}.json"

    def has_bag(self, bag_id: str) -> bool:
        return self._manifest(bag_id).exists()

    def commit_bag(
        self,
        bag_id: str,
        events: Sequence[Event],
        *,
        robot: str,
        start_ns: int | None,
        report: Mapping[str, Any],
    ) -> Commit:
        import pyarrow as pa
        import pyarrow.parquet as pq

        streams = sorted({e.stream for e in events if not e.stream.startswith("bag:")})
        run = streams[0] if len(streams) == 1 else f"bag-{bag_id[:16]}"
        date = dt.datetime.fromtimestamp((start_ns or 0) / 1e9, dt.UTC).date().isoformat()
        final = (
            self.root
            / f"robot={_part(robot)}"
            / f"date={date}"
            / f"run={_part(run)}"
            / f"bag-{bag_id}.parquet"
        )
        if not events:  # nothing to query; the manifest alone makes a re-ingest a no-op
            new = not self.has_bag(bag_id)
            self._write_manifest(bag_id, None, 0, report)
            return Commit(bag_id, None, 0, new=new)
        if self.has_bag(bag_id) or final.exists():
            self._write_manifest(bag_id, final, len(events), report)
            return Commit(bag_id, final, len(events), new=False)
        try:
            staging = self.root / STAGING
            staging.mkdir(parents=True, exist_ok=True)
            tmp = staging / f"{bag_id}.{uuid.uuid4().hex}.parquet"
            table = pa.table(
                {
                    "event_id": pa.array([e.event_id for e in events], pa.string()),
                    "stream": pa.array([e.stream for e in events], pa.string()),
                    "seq": pa.array([e.seq for e in events], pa.int64()),
                    "time_ns": pa.array([e.time_ns for e in events], pa.int64()),
                    "recorded_at_ns": pa.array([e.recorded_at_ns for e in events], pa.int64()),
                    "type": pa.array([e.type for e in events], pa.string()),
                    "version": pa.array([e.version for e in events], pa.int32()),
                    "task_id": pa.array([e.task_id for e in events], pa.string()),
                    "payload": pa.array([_payload_json(e) for e in events], pa.string()),
                    "bag_id": pa.array([bag_id] * len(events), pa.string()),
                }
            )
            pq.write_table(table, tmp, compression="zstd")
            with tmp.open("rb+") as fh:
                os.fsync(fh.fileno())
            final.parent.mkdir(parents=True, exist_ok=True)
            os.replace(tmp, final)
            _fsync_dir(final.parent)
        except OSError as exc:
            raise LakeError(f"committing bag {bag_id[:16]} to {self.root} failed: {exc}") from exc
        finally:
            if "tmp" in locals() and tmp.exists():
                tmp.unlink()
        self._write_manifest(bag_id, final, len(events), report)
        return Commit(bag_id, final, len(events), new=True)

    def _write_manifest(
        self, bag_id: str, final: Path | None, events: int, report: Mapping[str, Any]
    ) -> None:
        path = self._manifest(bag_id)
        if path.exists():
            return
        path.parent.mkdir(parents=True, exist_ok=True)
        file = None if final is None else str(final.relative_to(self.root))
        doc = {"bag_id": bag_id, "file": file, "events": events, "report": report}
        tmp = path.with_suffix(f".{uuid.uuid4().hex}.tmp")
        tmp.write_text(json.dumps(doc, indent=1, sort_keys=True, default=str), encoding="utf-8")
        os.replace(tmp, path)

    def events(self) -> Iterator[Event]:
        """Every event in the lake (for tests and small lakes; analysts use DuckDB)."""
        import pyarrow.parquet as pq

        for f in sorted(self.root.glob("robot=*/date=*/run=*/bag-*.parquet")):
            for row in pq.read_table(f, columns=list(COLUMNS[:-1])).to_pylist():
                row["payload"] = json.loads(row["payload"])
                yield Event.from_json_dict(row)


def _payload_json(e: Event) -> str:
    return json.dumps(dict(e.payload), sort_keys=True, separators=(",", ":"), ensure_ascii=False)
