"""Where ingested bags go: the fleet lake (:class:`objsearch.events.lake.TableLake`), one run per
recording.

Ingest needs three things of the lake, behind the :class:`LakeWriter` seam: which bags are in it
already (``known_pieces``, handed to workers so they skip those bags without reading them), to
keep the report of a bag that made no run, and to commit a bag into its run (``commit_piece``).
:class:`FleetBagLake` does them with the fleet lake's Delta table (in a folder or a bucket), so
bags and added agent logs share one table, one set of columns and one set of DuckDB views: a
bag's run is ``run = bag-<16 hex>`` in it, and its ingest record (the session and every piece's
report) the run's ``_ingest.json`` attachment; a bag that makes no run is recorded in the bags'
ledger (:mod:`~objsearch.pipeline.bags.ledger`), a row of its own outside any run.

A run holds one recording session (:mod:`~objsearch.pipeline.bags.session`): ``bag-`` and the
agent run id's first 16 hex digits when its events prove it, else its lowest agent event id's
(a provisional run, renamed as earlier pieces arrive), else the bag id's (a bag with no agent
events and no session's receive times around it). A piece whose agent run the lake holds other
than as this robot's bag session (a compacted log, another robot's) is refused naming that run:
an event id is in the lake at most once.

A bag's run, its report and the runs merged into it are one Delta transaction, so a reader sees
all of a bag or none of it; committing a bag twice is a no-op (see :class:`FleetBagLake`).
:func:`open_bag_lake` opens the lake at an address, refusing a per-run-folder lake
(``objsearch lake upgrade`` migrates it). The session logic is :class:`_SessionLake`'s, kept
apart from the table's reads and commit.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import logging
import random
import time
from abc import ABC, abstractmethod
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import pyarrow as pa
import pyarrow.compute as pc

from objsearch.agent.catalogue import STORE
from objsearch.events import Event, EventStoreError, read_log
from objsearch.events.envelope import deterministic_event_id
from objsearch.events.lake import LakeError, TableRaceLost, TableRun, is_table_lake, open_lake
from objsearch.events.lake.transactions import COMMIT_TRIES, STAMP_INDEX_APP
from objsearch.events.log_files import read_meta
from objsearch.pipeline.bags.clock import clock_from_doc, fit_clock, pairs_from_doc
from objsearch.pipeline.bags.errors import BagCommitError
from objsearch.pipeline.bags.ledger import bag_records, record_bag
from objsearch.pipeline.bags.session import (
    DERIVED_PREFIX,
    FirstEvent,
    Span,
    agent_rows,
    belongs,
    continues,
    disagreements,
    merge_tables,
    overlaps,
    provisional_run_name,
    same_ids,
    session_run_name,
    spans_of,
)

if TYPE_CHECKING:
    import polars as pl

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

    @property
    def received(self) -> tuple[int, int] | None:
        return _received(self.report, self.start_ns, self.end_ns)


def _received(report: Mapping[str, Any], start_ns: Any, end_ns: Any) -> tuple[int, int] | None:
    """A piece's receive-time range (its report's; a report from before there was one gives
    its time range, which was the receive time then)."""
    start = report.get("received_start_ns", start_ns)
    end = report.get("received_end_ns", end_ns)
    return (int(start), int(end)) if start is not None and end is not None else None


def _receive_ranges(docs: Iterable[Mapping[str, Any]]) -> dict[bool, tuple[int, int]]:
    """The receive times a session's pieces with agent events span, per receive clock: True for
    the pieces whose receive times are mapped onto the agent's clock (they kept clock pairs: a
    playback recorded again), False for those already on it (``record``'s bags). Two
    recordings of one run on different clocks (a bag and its re-recording) are not one span."""
    spans: dict[bool, list[tuple[int, int]]] = {}
    for doc in docs:
        if not doc.get("agent", True):  # pieces recorded before the flag all had agent events
            continue
        report = doc.get("report") or {}
        received = _received(report, doc.get("start_ns"), doc.get("end_ns"))
        if received is not None:
            clocked = bool(pairs_from_doc(report.get("clock_pairs")))
            spans.setdefault(clocked, []).append(received)
    return {k: (min(a for a, _ in v), max(b for _, b in v)) for k, v in spans.items()}


def _widens(session: _SessionRun, piece: Piece) -> bool:
    """Whether a piece with agent events, all of them in ``session`` already, is received
    outside the session's pieces on its receive clock: another recording of the session (its
    rows kept once, judged by what was recorded), which stays a piece of it, so that its
    receive times and clock pairs place the stretches recorded with it that hold no agent
    events. A copy of a piece the session holds is not."""
    if piece.first is None or piece.received is None:
        return False
    clocked = bool(pairs_from_doc(piece.report.get("clock_pairs")))
    span = _receive_ranges(session.pieces.values()).get(clocked)
    return span is None or not (span[0] <= piece.received[0] and piece.received[1] <= span[1])


def _encloses(ranges: Mapping[bool, tuple[int, int]], received: tuple[int, int] | None) -> bool:
    return received is not None and any(
        a <= received[0] and received[1] <= b for a, b in ranges.values()
    )


@dataclass(frozen=True, slots=True)
class Commit:
    bag_id: str
    events: int  # events the lake gained
    new: bool  # False when the bag added nothing (it, or its events, were already in the lake)
    run: str = ""  # the run that holds the bag's session
    note: str = ""  # what happened, when it is more than "committed"


class LakeWriter(Protocol):
    #: Whether :meth:`pieces_known` answers for given bag ids (then ingest hashes the bags
    #: first, once) rather than :meth:`known_pieces` listing every bag the lake holds.
    asks_by_bag_id: bool

    def known_pieces(self) -> Mapping[str, str]: ...

    def pieces_known(self, bag_ids: Sequence[str], converter: str) -> Mapping[str, str] | None: ...

    def record_without_run(self, bag_id: str, report: dict[str, Any]) -> None: ...

    def commit_piece(self, piece: Piece, *, robot: str) -> Commit: ...


def run_name(bag_id: str) -> str:
    return RUN_PREFIX + bag_id[:16]


@dataclass(frozen=True, slots=True)
class _SessionRun:
    info: TableRun
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
    def spans(self) -> dict[str, Span]:
        docs = self.doc.get("session", {}).get("spans")
        if not isinstance(docs, dict):
            return {}
        spans = {str(k): Span.from_doc(str(k), v) for k, v in docs.items()}
        return {k: v for k, v in spans.items() if v is not None}

    @property
    def received(self) -> tuple[int, int] | None:
        """The receive times its pieces span."""
        ranges = [
            r
            for p in self.pieces.values()
            if (r := _received(p.get("report") or {}, p.get("start_ns"), p.get("end_ns")))
        ]
        if not ranges:
            return None
        return min(a for a, _ in ranges), max(b for _, b in ranges)

    @property
    def pieces(self) -> Mapping[str, Mapping[str, Any]]:
        pieces = self.doc.get("pieces")
        if isinstance(pieces, dict):
            return pieces
        # A run written before sessions: one bag, its report doc as a whole.
        return {str(self.doc["bag_id"]): self.doc} if "bag_id" in self.doc else {}


def open_bag_lake(root: Path | str) -> FleetBagLake:
    """The fleet lake ingest writes to at ``root`` (an object-store URI or a folder): one that
    is there, or a new one in a missing or empty folder. A per-run-folder lake is refused
    (``objsearch lake upgrade`` migrates it), and so is a folder holding anything else."""
    return FleetBagLake(root)


class _SessionLake(ABC):
    """What ingest does with recording sessions, whichever lake keeps the runs: the abstract
    hooks below are each lake's reads and its commit."""

    @abstractmethod
    def _all_runs(self) -> Sequence[TableRun]: ...

    @abstractmethod
    def _run_doc(self, info: TableRun) -> bytes | str | None:
        """A bag run's ``_ingest.json`` (None if it has none)."""
        ...

    @abstractmethod
    def _read(self, info: TableRun) -> Mapping[str, pa.Table]: ...

    @abstractmethod
    def _held_ids(self, info: TableRun) -> set[str]: ...

    @abstractmethod
    def _store(
        self,
        tables: Mapping[str, pa.Table],
        *,
        robot: str,
        run: str,
        source: str,
        existing: _SessionRun | None,
        absorbed: Sequence[_SessionRun],
        doc: Mapping[str, Any],
        identity: Mapping[str, str],
    ) -> None:
        """Commit a session's run (replacing ``existing``, taking out ``absorbed``) and the
        pieces' records."""
        ...

    @abstractmethod
    def _write_report(self, bag_id: str, data: bytes) -> None: ...

    def _sessions(self, runs: Sequence[TableRun] | None = None) -> list[_SessionRun]:
        """Every bag run with its ingest record."""
        found = []
        for info in self._all_runs() if runs is None else runs:
            if not info.run.startswith(RUN_PREFIX):
                continue
            try:
                text = self._run_doc(info)
                doc = json.loads(text) if text is not None else {}
            except (OSError, ValueError):
                doc = {}
            found.append(_SessionRun(info, doc if isinstance(doc, dict) else {}))
        return found

    def _commit_locked(self, piece: Piece, robot: str) -> Commit:
        runs = self._all_runs()
        sessions = [s for s in self._sessions(runs) if s.info.robot == robot]
        rows = agent_rows(piece.tables)
        run_id = piece.run_id or self._proven_run_id(piece.first, runs)
        if run_id:
            self._refuse_other_holder(piece, run_id, robot, runs)
        elif not rows.is_empty():
            self._refuse_held_ids(piece, rows, runs)
        related = self._same_recording(piece, run_id, rows, sessions)
        firsts = [f for f in [piece.first, *(s.first for s in related)] if f is not None]
        first = min(firsts, key=lambda f: (f.stream, f.seq)) if firsts else None
        run, run_id, joined = _run_of(piece, run_id, rows, related, first)
        existing = next((s for s in sessions if s.info.run == run), None)
        previous = [existing] if existing is not None else []
        previous += [s for s in related if s is not existing]
        absorbed = [s for s in previous if s is not existing]
        redo = False
        holder = next((s for s in previous if piece.bag_id in s.pieces), None)
        if holder is not None:
            same = holder.pieces[piece.bag_id].get("converter") == piece.converter
            if same and not piece.reingest and holder is existing and not absorbed:
                return Commit(piece.bag_id, 0, new=False, run=run)
            redo = True  # read again with another topic map or converter: replace its rows
        old_tables = [self._read(s.info) for s in previous]
        pieces: dict[str, Mapping[str, Any]] = {}
        for s in previous:
            pieces.update(s.pieces)
        pieces[piece.bag_id] = self._piece_doc(piece, robot, run)
        clock = fit_clock(
            pair
            for p in pieces.values()
            for pair in pairs_from_doc((p.get("report") or {}).get("clock_pairs"))
        )
        tables: Mapping[str, pa.Table] = piece.tables
        # Messages this bag and the session's other recordings hold differently at one header
        # stamp: one of them is damaged, and nothing tells which; both rows are kept.
        differ = disagreements([*old_tables, piece.tables]) if old_tables else {}
        if differ:
            pieces[piece.bag_id] = {**pieces[piece.bag_id], "disagreements": differ}
        if old_tables or first is not None or clock is not None:
            # A session's derived events are numbered in its own stream, whichever piece came
            # first, so the run does not depend on the order the pieces arrived in.
            received = piece.received
            drop = [received] if redo and received is not None else []
            tables = merge_tables(
                [*old_tables, piece.tables],
                DERIVED_PREFIX + run.removeprefix(RUN_PREFIX),
                drop,
                clock,
                _receive_ranges(pieces.values()).get(True),
                # The clock each part's rows timed by their receive time were put on.
                [
                    *(clock_from_doc(s.doc.get("session", {}).get("clock")) for s in previous),
                    clock_from_doc(piece.report.get("clock")),
                ],
            )
        before = sum(t.num_rows for ts in old_tables for t in ts.values())
        events = sum(t.num_rows for t in tables.values())
        if (
            existing is not None
            and not absorbed
            and not redo
            and events == before
            and not _widens(existing, piece)
        ):
            # Every event of this bag is in the run already: the same recording again.
            doc = self._piece_doc(piece, robot, existing.info.run, duplicate=True)
            self._write_report(piece.bag_id, _json(doc))
            return Commit(
                piece.bag_id,
                0,
                new=False,
                run=run,
                note=f"its events are already in the lake in run {existing.info.run} "
                "(the same recording, ingested before); nothing added",
            )
        pieces = {k: {**v, "run": run} for k, v in sorted(pieces.items())}
        session = {
            "run_id": run_id,
            "first": dataclasses.asdict(first) if first else None,
            "spans": {k: v.to_doc() for k, v in sorted(spans_of(agent_rows(tables)).items())},
            "clock": dataclasses.asdict(clock) if clock else None,
        }
        doc = {"session": session, "pieces": pieces}
        self._store(
            tables,
            robot=robot,
            run=run,
            source=f"bag session {run_id or run}" if first else f"bag:{piece.bag_id}",
            existing=existing,
            absorbed=absorbed,
            doc=doc,
            identity={"run_id": run_id} if run_id else {},
        )
        note = _commit_note(run, joined, len(pieces), differ)
        return Commit(piece.bag_id, events - before, new=True, run=run, note=note)

    @staticmethod
    def _proven_run_id(first: FirstEvent | None, runs: Sequence[TableRun]) -> str | None:
        """The run id, among those the lake's runs record (bag sessions and compacted logs),
        that the piece's lowest event id proves it belongs to."""
        if first is None:
            return None
        candidates = sorted({r.identity["run_id"] for r in runs if r.identity.get("run_id")})
        return next((c for c in candidates if belongs(c, first)), None)

    @staticmethod
    def _refuse_other_holder(
        piece: Piece, run_id: str, robot: str, runs: Sequence[TableRun]
    ) -> None:
        """A run id the lake holds other than as this robot's bag session: refused."""
        for other in runs:
            if other.identity.get("run_id") != run_id:
                continue
            if other.run.startswith(RUN_PREFIX) and other.robot == robot:
                continue
            raise BagCommitError(
                f"bag {piece.bag_id[:16]}'s agent events belong to agent run {run_id}, which "
                f"the lake already holds as run {other.run!r} of robot {other.robot!r} "
                f"({other.source}); ingesting it would count its events twice"
            )

    def _refuse_held_ids(self, piece: Piece, rows: pl.DataFrame, runs: Sequence[TableRun]) -> None:
        """A piece whose run nothing proves, whose event ids a run that is no bag session
        holds (a compacted log that records no run id): refused naming that run."""
        ids = set(rows["event_id"].to_list())
        for other in runs:
            if other.run.startswith(RUN_PREFIX) or other.identity.get("run_id"):
                continue  # bag sessions are matched by their ids; run ids were checked
            held = other.identity.get("first_event_id") in ids or bool(ids & self._held_ids(other))
            if held:
                raise BagCommitError(
                    f"bag {piece.bag_id[:16]}'s agent events are already in the lake in run "
                    f"{other.run!r} of robot {other.robot!r} ({other.source}); ingesting it "
                    "would count them twice"
                )

    def _same_recording(
        self,
        piece: Piece,
        run_id: str | None,
        rows: pl.DataFrame,
        sessions: Sequence[_SessionRun],
    ) -> list[_SessionRun]:
        """The stored sessions (of this robot) that are this piece's recording."""
        related: list[_SessionRun] = []
        if rows.is_empty():
            if run_id is None:
                enclosing = [
                    s
                    for s in sessions
                    if s.first is not None
                    and _encloses(_receive_ranges(s.pieces.values()), piece.received)
                ]
                if len(enclosing) == 1:
                    related = enclosing
            return related
        spans = spans_of(rows)
        for s in sessions:
            if s.run_id is not None or s.first is None:
                continue
            if run_id is not None:
                if belongs(run_id, s.first):
                    related.append(s)
                continue
            theirs = s.spans
            if any(overlaps(a, b) for a in spans.values() for b in theirs.values()):
                if same_ids(rows, agent_rows(self._read(s.info))):
                    related.append(s)
            elif any(continues(a, b) for a in spans.values() for b in theirs.values()):
                related.append(s)
        # Stretches without agent events stored before their session was known: absorbed
        # when the session's receive times (with this piece) enclose them.
        mine = [*related, *(s for s in sessions if run_id is not None and s.run_id == run_id)]
        docs = [self._piece_doc(piece, "", ""), *(p for s in mine for p in s.pieces.values())]
        ranges = _receive_ranges(docs)
        related += [
            s
            for s in sessions
            if s.first is None
            and s.run_id is None
            and s not in related
            and _encloses(ranges, s.received)
        ]
        return related

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
            "agent": piece.first is not None,  # holds agent events
            "report": piece.report,
        }
        if duplicate:
            doc["duplicate_of"] = run
        return doc


def refuse_a_log_a_session_holds(log_dir: Path, root: Path | str) -> None:
    """An event id is in the lake at most once: raise :class:`LakeError` if a bag session's
    provisional run — pieces of a recording that started after ``run_started``, ingested
    first, so its run id is not known — holds events of the agent log at ``log_dir``, naming
    it (``lake add`` asks before adding the log). Such a run's lowest agent event is in its
    ingest record; it is the log's if it is on the log's stream with the log's own id for its
    seq, uuid5(run id, seq). Reads the ``_run`` rows of bag runs that record no run id, no
    event."""
    first = next(read_log(log_dir, store=STORE), None)
    if first is None or not is_table_lake(root):
        return
    id_key = read_meta(log_dir).id_key()
    bags = FleetBagLake(root)
    bag_runs = bags.lake._runs(bags._current(), pc.starts_with(pc.field("run"), RUN_PREFIX))
    for session in bags._sessions(bag_runs):
        held = session.first
        if session.run_id or held is None or held.stream != first.stream:
            continue
        if held.event_id == deterministic_event_id(id_key, held.seq):
            raise LakeError(
                f"event log {log_dir} is already partly in the lake: run "
                f"{session.info.run!r} of robot {session.info.robot!r} (from "
                f"{session.info.source}) holds its event seq {held.seq} ({held.event_id}); "
                "adding the log would count those events twice. Take that run out of the lake "
                "first (the log holds every event the recording has)"
            )


#: The application transaction every bag commit of a robot carries (``objsearch/bags/<robot>``):
#: two ingests of one robot's bags decide their commits from the table one at a time, as the
#: folder lake's lock makes them.
def bags_app(robot: str) -> str:
    return f"objsearch/bags/{robot}"


def piece_stamps(bag_id: str, converter: str) -> list[str]:
    """The application transactions a commit recording bag ``bag_id`` (read with ``converter``)
    stamps (:func:`~objsearch.events.lake.transactions.stamp_version`): the bag's, and the bag's with
    that converter. The bag is in the lake read with ``converter`` when both stamps are equal
    (the latest commit that recorded it recorded that converter)."""
    return [f"objsearch/piece/{bag_id}", f"objsearch/piece/{bag_id}@{converter}"]


def _doc_stamps(bag_id: str, doc: Mapping[str, Any]) -> list[str]:
    return piece_stamps(bag_id, str(doc.get("converter", "")))


def _run_of(
    piece: Piece,
    run_id: str | None,
    rows: pl.DataFrame,
    related: Sequence[_SessionRun],
    first: FirstEvent | None,
) -> tuple[str, str | None, str]:
    """The run a piece goes into, its session's run id, and the run it joined ("" if none)."""
    if run_id:
        return session_run_name(run_id), run_id, ""
    if rows.is_empty() and related:
        # A stretch without agent events, inside that session's receive times.
        return related[0].info.run, related[0].run_id, related[0].info.run
    if first is not None:
        return provisional_run_name(first), run_id, ""
    return run_name(piece.bag_id), run_id, ""


def _commit_note(run: str, joined: str, bags: int, differ: Mapping[str, int]) -> str:
    """What a commit says of the run a piece went into."""
    note = ""
    if joined:
        note = (
            f"joined run {run}: it holds no agent events and its receive times lie within "
            f"that recording's ({bags} bags)"
        )
    elif bags > 1:
        note = f"merged into run {run} ({bags} bags of one recording session)"
    if differ:
        said = ", ".join(f"{n} {t}" for t, n in sorted(differ.items()))
        note += (
            f"{'; ' if note else ''}{said} message(s) recorded differently by this bag and "
            "the session's other recording(s) at the same header stamp: one copy is damaged "
            "and nothing tells which, so both are kept"
        )
    return note


class FleetBagLake(_SessionLake):
    """:class:`LakeWriter` over the fleet lake (:class:`~objsearch.events.lake.TableLake`,
    a folder or a bucket). A bag's run — its events, derived tables and the session's ingest
    record (``_ingest.json``: every piece's report) — and the runs merged into it are **one**
    Delta transaction, decided from one version of the table and carrying the application
    transactions of those runs and :func:`bags_app` of the robot: if another commit of them
    came since, it fails and is decided again from the table as it is then (no lock, no
    staging folder; nothing to finish after a crash). A bag that makes no run, or whose events
    the lake holds already, is recorded in a row of its own (``type = '_bag'``): the lake
    accounts for every bag it was given. Each commit also stamps the bags it records
    (:func:`piece_stamps`), so whether a bag is here is a look-up in the table's log
    (:meth:`pieces_known`), whatever the number of runs."""

    asks_by_bag_id = True

    def __init__(self, root: Path | str) -> None:
        self.root = root
        self.lake = open_lake(root, store=STORE)
        self._table: Any = None

    def _current(self) -> Any:
        """The table as this commit decides from it (loaded once per try)."""
        if self._table is None:
            self.lake.create()
            self._table = self.lake.table()
        return self._table

    def _all_runs(self) -> Sequence[TableRun]:
        return self.lake.runs(self._current())

    def _run_doc(self, info: TableRun) -> bytes | str | None:
        assert isinstance(info, TableRun)
        return info.attachments.get(RUN_REPORT)

    def _read(self, info: TableRun) -> Mapping[str, pa.Table]:
        assert isinstance(info, TableRun)
        return self.lake.read_tables(info, self._current())

    def _held_ids(self, info: TableRun) -> set[str]:
        return {str(i) for t in self._read(info).values() for i in t["event_id"].to_pylist()}

    def _store(
        self,
        tables: Mapping[str, pa.Table],
        *,
        robot: str,
        run: str,
        source: str,
        existing: _SessionRun | None,
        absorbed: Sequence[_SessionRun],
        doc: Mapping[str, Any],
        identity: Mapping[str, str],
    ) -> None:
        replacing = [s.info.run for s in ([existing] if existing is not None else [])]
        self.lake.commit_as_read(
            self._current(),
            tables,
            robot=robot,
            run=run,
            date=_date(tables),
            source=source,
            attachments={RUN_REPORT: _json(doc).decode()},
            identity=identity,
            replacing=replacing + [s.info.run for s in absorbed],
            apps=[bags_app(robot)],
            stamps=[a for k, v in sorted(doc["pieces"].items()) for a in _doc_stamps(k, v)],
        )

    def _write_report(self, bag_id: str, data: bytes) -> None:
        doc = json.loads(data)
        robot = doc.get("robot")
        record_bag(
            self.lake,
            bag_id,
            str(robot) if robot else None,
            data.decode(),
            _doc_stamps(bag_id, doc),
        )

    def known_pieces(self) -> dict[str, str]:
        """Bag id → the converter key it was read with, for every bag the lake has taken: the
        pieces its bag runs record, and the bags recorded outside any run."""
        return {bag_id: str(doc.get("converter", "")) for bag_id, doc in self.piece_docs().items()}

    def piece_docs(self) -> dict[str, Mapping[str, Any]]:
        """Bag id → what the lake recorded of it (its ``report``, ``run``, ``converter``, …),
        for every bag the lake has taken."""
        self._table = None
        table = self._current()
        docs: dict[str, Mapping[str, Any]] = {}
        for bag_id, text in bag_records(self.lake, table).items():
            doc = json.loads(text)
            docs[bag_id] = doc if isinstance(doc, dict) else {}
        for s in self._sessions(self.lake.runs(table)):
            docs.update(s.pieces)
        return dict(sorted(docs.items()))

    def pieces_known(self, bag_ids: Sequence[str], converter: str) -> Mapping[str, str] | None:
        """Bag id → ``converter`` for those of ``bag_ids`` the lake holds read with it (the
        others are read by ingest), from the table's log alone (:func:`piece_stamps`): no row
        is read. A bag not read with ``converter`` costs one look-up, one that was two (its
        stamp with the converter, then whether that stamp is the bag's latest). None for a
        table made before commits stamped bags (then :meth:`known_pieces` reads every record)."""
        self._table = None
        table = self._current()
        self._table = None
        if table.transaction_version(STAMP_INDEX_APP) is None:
            return None
        known = {}
        for bag_id in bag_ids:
            latest, with_converter = piece_stamps(bag_id, converter)
            stamped = table.transaction_version(with_converter)
            if stamped is not None and table.transaction_version(latest) == stamped:
                known[bag_id] = converter
        return known

    def record_without_run(self, bag_id: str, report: dict[str, Any]) -> None:
        doc = {"bag_id": bag_id, "robot": None, "run": None, "events": 0, "report": report}
        try:
            record_bag(self.lake, bag_id, None, _json(doc).decode(), _doc_stamps(bag_id, doc))
        except (OSError, EventStoreError) as exc:
            raise BagCommitError(f"writing the report of bag {bag_id[:16]} failed: {exc}") from exc

    def commit_piece(self, piece: Piece, *, robot: str) -> Commit:
        """Commit a bag into its session's run (see the class); decided again while other
        commits of this robot's bags come between the read and the commit."""
        for attempt in range(COMMIT_TRIES):
            self._table = None
            try:
                return self._commit_locked(piece, robot)
            except TableRaceLost as exc:
                _log.debug("%s: %s; deciding again", self.root, exc)
                time.sleep(min(0.5, 0.02 * (attempt + 1)) * (1 + random.random()))
            except (OSError, EventStoreError) as exc:
                raise BagCommitError(
                    f"committing bag {piece.bag_id[:16]} to {self.root} failed: {exc}"
                ) from exc
            finally:
                self._table = None
        raise BagCommitError(
            f"committing bag {piece.bag_id[:16]} to {self.root} lost {COMMIT_TRIES} races with "
            "other writers of this robot's bags; run the command again"
        )

    def events(self) -> Iterator[Event]:
        """Every event of every ingested bag (tests and small lakes; analysts use DuckDB)."""
        for info in self.lake.runs():
            if info.run.startswith(RUN_PREFIX):
                yield from self.lake.read_events(info)


def _date(tables: Mapping[str, pa.Table]) -> dt.date:
    """The UTC date of a run's earliest event."""
    starts = [pc.min(t["time_ns"]).as_py() for t in tables.values() if t.num_rows]
    first = min((s for s in starts if s is not None), default=0)
    return dt.datetime.fromtimestamp(first / 1e9, dt.UTC).date()


def _json(doc: Mapping[str, Any]) -> bytes:
    return json.dumps(doc, indent=1, sort_keys=True, default=str).encode() + b"\n"
