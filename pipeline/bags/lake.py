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

import dataclasses
import datetime as dt
import json
import logging
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import pyarrow as pa

from objsearch.events import Event, EventStoreError, _fs
from objsearch.events.lake import Lake, RunInfo
from objsearch.pipeline.bags.errors import BagCommitError
from objsearch.pipeline.bags.session import (
    DERIVED_PREFIX,
    FirstEvent,
    belongs,
    merge_tables,
    session_run_name,
)

MANIFESTS = "_bags"
RUN_PREFIX = "bag-"
RUN_REPORT = "_ingest.json"  # the report's copy inside the run, committed with it

_log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Piece:
    """One bag, converted: what the driver commits (see :mod:`~objsearch.pipeline.bags.session`)."""

    bag_id: str
    tables: Mapping[str, pa.Table]
    report: Mapping[str, Any]
    start_ns: int | None
    end_ns: int | None
    converter: str  # :func:`~objsearch.pipeline.bags.session.converter_key` it was read with
    run_id: str | None = None  # the agent run it proved it belongs to (from its run_started)
    first: FirstEvent | None = None  # its lowest-seq agent event
    reingest: bool = False  # replace its rows even if the lake has it with this converter

    @property
    def events(self) -> int:
        return sum(t.num_rows for t in self.tables.values())


@dataclass(frozen=True, slots=True)
class Commit:
    bag_id: str
    path: Path | None  # the run's folder
    events: int  # events the lake gained
    new: bool  # False when the bag added nothing (it, or its events, were already in the lake)
    run: str = ""  # the run that holds the bag's session
    note: str = ""  # what happened, when it is more than "committed"


class LakeWriter(Protocol):
    def known_pieces(self) -> Mapping[str, str]: ...

    def record_without_run(self, bag_id: str, report: dict[str, Any]) -> None: ...

    def restore_report(self, bag_id: str) -> bool: ...

    def commit_piece(self, piece: Piece, *, robot: str) -> Commit: ...


def run_name(bag_id: str) -> str:
    return RUN_PREFIX + bag_id[:16]


@dataclass(frozen=True, slots=True)
class _SessionRun:
    info: RunInfo
    doc: Mapping[str, Any]  # its _ingest.json: {"session": {...}, "pieces": {bag id: manifest}}

    @property
    def run_id(self) -> str | None:
        rid = self.doc.get("session", {}).get("run_id")
        return str(rid) if rid else None

    @property
    def first(self) -> FirstEvent | None:
        first = self.doc.get("session", {}).get("first")
        return FirstEvent(**first) if first else None

    @property
    def pieces(self) -> Mapping[str, Mapping[str, Any]]:
        pieces = self.doc.get("pieces")
        if isinstance(pieces, dict):
            return pieces
        # A run written before sessions: one bag, its report doc as a whole.
        return {str(self.doc["bag_id"]): self.doc} if "bag_id" in self.doc else {}


class BagLake:
    """:class:`LakeWriter` over the event store's :class:`~objsearch.events.lake.Lake`."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.lake = Lake(self.root)

    def _sessions(self) -> list[_SessionRun]:
        """Every bag run with its ingest record (one small file a run)."""
        found = []
        for info in self.lake.runs():
            if not info.run.startswith(RUN_PREFIX):
                continue
            try:
                doc = json.loads((info.path / RUN_REPORT).read_bytes())
            except (OSError, ValueError):
                doc = {}
            found.append(_SessionRun(info, doc if isinstance(doc, dict) else {}))
        return found

    def known_pieces(self) -> dict[str, str]:
        """Bag id → the converter key it was read with, for every bag the lake has taken (from
        ``_bags/``: one small file a bag)."""
        known = {}
        for path in sorted((self.root / MANIFESTS).glob("*.json")):
            try:
                doc = json.loads(path.read_bytes())
            except (OSError, ValueError):
                continue
            if isinstance(doc, dict):
                known[path.stem] = str(doc.get("converter", ""))
        return known

    def has_bag(self, bag_id: str) -> bool:
        return any(bag_id in s.pieces for s in self._sessions())

    def commit_piece(self, piece: Piece, *, robot: str) -> Commit:
        """Commit a bag into its session's run, under the lake's lock: a new run, or the
        session's run replaced by the merge of what it held and this piece (absorbing
        provisional runs of the session's later pieces). See :mod:`..session`."""
        try:
            with self.lake.locked():
                return self._commit_locked(piece, robot)
        except (OSError, EventStoreError) as exc:
            raise BagCommitError(
                f"committing bag {piece.bag_id[:16]} to {self.root} failed: {exc}"
            ) from exc

    def _commit_locked(self, piece: Piece, robot: str) -> Commit:
        sessions = [s for s in self._sessions() if s.info.robot == robot]
        candidates = sorted({s.run_id for s in sessions if s.run_id})
        run_id = piece.run_id
        if run_id is None and piece.first is not None:
            run_id = next((c for c in candidates if belongs(c, piece.first)), None)
        run = session_run_name(run_id) if run_id else run_name(piece.bag_id)
        if run_id:
            for other in self.lake.holding({"run_id": run_id}):
                if not other.run.startswith(RUN_PREFIX):
                    raise BagCommitError(
                        f"bag {piece.bag_id[:16]} records agent run {run_id}, which the lake "
                        f"already holds as run {other.run!r} of robot {other.robot!r} "
                        f"({other.source}); ingesting it would count its events twice"
                    )
        existing = next((s for s in sessions if s.info.run == run), None)
        redo = False
        if existing is not None and piece.bag_id in existing.pieces:
            same = existing.pieces[piece.bag_id].get("converter") == piece.converter
            if same and not piece.reingest:
                self.restore_report(piece.bag_id)
                return Commit(piece.bag_id, existing.info.path, 0, new=False, run=run)
            redo = True  # read again with another topic map or converter: replace its rows
        absorbed = [
            s
            for s in sessions
            if run_id
            and s is not existing
            and s.run_id is None
            and s.first is not None
            and belongs(run_id, s.first)
        ]
        previous = [existing, *absorbed] if existing is not None else absorbed
        old_tables = [self.lake.read_tables(s.info) for s in previous]
        tables: Mapping[str, pa.Table] = piece.tables
        if old_tables or run_id:
            # A session's derived events are numbered in its own stream, whichever piece came
            # first, so the run does not depend on the order the pieces arrived in.
            drop = [(piece.start_ns, piece.end_ns)] if redo else []
            tables = merge_tables(
                [*old_tables, piece.tables],
                DERIVED_PREFIX + run.removeprefix(RUN_PREFIX),
                [(a, b) for a, b in drop if a is not None and b is not None],
            )
        before = sum(t.num_rows for ts in old_tables for t in ts.values())
        events = sum(t.num_rows for t in tables.values())
        if existing is not None and not absorbed and not redo and events == before:
            # Every event of this bag is in the run already: the same recording again.
            doc = self._piece_doc(piece, robot, existing.info.run, duplicate=True)
            self._write_report(piece.bag_id, _json(doc))
            return Commit(
                piece.bag_id,
                existing.info.path,
                0,
                new=False,
                run=run,
                note=f"its events are already in the lake in run {existing.info.run} "
                "(the same recording, ingested before); nothing added",
            )
        pieces: dict[str, Mapping[str, Any]] = {}
        for s in previous:
            pieces.update(s.pieces)
        pieces[piece.bag_id] = self._piece_doc(piece, robot, run)
        pieces = {k: {**v, "run": run} for k, v in sorted(pieces.items())}
        starts = [int(p["start_ns"]) for p in pieces.values() if p.get("start_ns") is not None]
        date = dt.datetime.fromtimestamp(min(starts, default=0) / 1e9, dt.UTC).date()
        firsts = [f for f in [piece.first, *(s.first for s in previous)] if f is not None]
        first = min(firsts, key=lambda f: (f.stream, f.seq)) if firsts else None
        session = {"run_id": run_id, "first": dataclasses.asdict(first) if first else None}
        doc = {"session": session, "pieces": pieces}
        info = self.lake.commit_tables(
            tables,
            robot=robot,
            run=run,
            date=date,
            source=f"bag session {run_id}" if run_id else f"bag:{piece.bag_id}",
            replace=existing is not None,
            attachments={RUN_REPORT: _json(doc)},
            identity={"run_id": run_id} if run_id else {},
        )
        for s in absorbed:
            self.lake.remove_run(s.info)
        for bag_id, piece_doc in pieces.items():
            self._write_report(bag_id, _json(piece_doc))
        note = ""
        if len(pieces) > 1:
            note = f"merged into run {run} ({len(pieces)} bags of one recording session)"
        return Commit(piece.bag_id, info.path, events - before, new=True, run=run, note=note)

    @staticmethod
    def _piece_doc(piece: Piece, robot: str, run: str, duplicate: bool = False) -> dict[str, Any]:
        doc = {
            "bag_id": piece.bag_id,
            "robot": robot,
            "run": run,
            "events": piece.events,
            "converter": piece.converter,
            "start_ns": piece.start_ns,
            "end_ns": piece.end_ns,
            "report": piece.report,
        }
        if duplicate:
            doc["duplicate_of"] = run
        return doc

    def record_without_run(self, bag_id: str, report: dict[str, Any]) -> None:
        """Keep the report of a bag that made no run (nothing in it to keep): what it claimed and
        lost is still accounted for in ``_bags/<bag id>.json``, with ``run`` null."""
        doc = {"bag_id": bag_id, "robot": None, "run": None, "events": 0, "report": report}
        try:
            with self.lake.locked():
                self._write_report(bag_id, _json(doc))
        except (OSError, EventStoreError) as exc:
            raise BagCommitError(f"writing the report of bag {bag_id[:16]} failed: {exc}") from exc

    def restore_report(self, bag_id: str) -> bool:
        """Write ``_bags/<bag id>.json`` from the run's record if a crash left it out; returns
        whether it did."""
        report = self.root / MANIFESTS / f"{bag_id}.json"
        if report.exists():
            return False
        docs = [s.pieces[bag_id] for s in self._sessions() if bag_id in s.pieces]
        if not docs:
            return False
        try:
            with self.lake.locked():
                if report.exists():
                    return False
                self._write_report(bag_id, _json(docs[0]))
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


def _json(doc: Mapping[str, Any]) -> bytes:
    return json.dumps(doc, indent=1, sort_keys=True, default=str).encode() + b"\n"
