"""One fleet-lake run's events as a stream, checked before the first is handed out.

``replay``, ``where`` and ``audit`` from a lake (:mod:`objsearch.replay.source`) fold a run's
events one at a time, as they fold a log. :meth:`TableLake.read_events` holds the whole run
(every row of every column as Arrow, then every event as Python: about 2 GB for a run of 1 M
events), so this reads it twice instead, a type at a time and a few thousand rows at a time,
from the run's files only (by the statistics the table's log records) and the columns of its
types only:

1. :meth:`RunReader.check`: every row of the run, hashed (:mod:`.run_digest`, version 2) and
   counted per type, as :meth:`TableLake.read_events` checks them — a run that does not read
   back as committed raises :class:`TableLakeError` before any event is handed out;
2. :meth:`RunReader.events`: the rows again, as events in ``(stream, seq)`` order (a merge of
   the types; a run of several streams, a bag's, a stream at a time). If a local file of the
   run was written to between the two reads (its size, mtime, ctime or inode changed) the
   iterator raises :class:`TableLakeError` at its end, before a fold's answer can be printed;
   hashing the rows again instead cost ~1 CPU-s a million events. An object store's objects
   are not rewritten in place (their names are their hashes).

A type whose rows do not come out of the files in seq order (no commit of this module writes
them so) is read whole and sorted, as :meth:`TableLake.read_tables` does. A run committed
with a version-1 digest (Arrow IPC bytes) is read whole by :meth:`TableLake.read_events`,
which knows how to check it.
"""

from __future__ import annotations

import bisect
import contextlib
import gc
import operator
import os
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.dataset as pds

from ..arrow import ENVELOPE_COLUMNS, event_schema, tables_to_events
from ..envelope import Event
from .run_digest import DIGEST_PREFIX, TypeDigest, combine, digest_version
from .schema import DataFile, TableLakeError, TableRun

if TYPE_CHECKING:
    from .fleet import TableLake

#: Rows a scan hands over at a time (Arrow) while the run is checked, one type at a time.
CHECK_ROWS: Final = 1 << 14
#: Rows a scan hands over at a time while the events are read: one scan a type is open at once,
#: and each holds about this many rows several times over (decoded, cast, read ahead): at 1 M
#: events a ``where`` peaked at 258 MB with 8 Ki rows, 201 MB with 2 Ki, 189 MB with 1 Ki.
SCAN_ROWS: Final = 1 << 10
#: Rows turned into Python events at a time: a merge holds one such slice per event type.
EVENT_ROWS: Final = 1 << 10
_ENVELOPE: Final = tuple(f.name for f in ENVELOPE_COLUMNS)


class RunReader:
    """Reads one committed run of ``lake`` (see the module); ``table``: the Delta table as
    just loaded, if the caller has it."""

    def __init__(self, lake: TableLake, run: TableRun, table: Any | None = None) -> None:
        self.lake = lake
        self.run = run
        self._table = lake.table() if table is None else table
        self._files: dict[str, list[DataFile]] | None = None
        #: The streams each type's rows are in (known once :meth:`check` ran).
        self.streams: dict[str, frozenset[str]] = {}
        self._unsorted: set[str] = set()
        self._whole: list[Event] | None = None  # a version-1 run, read whole
        self._checked = False
        self._checked_files: dict[str, tuple[int, int, int, int]] | None = None

    # -- reading rows -----------------------------------------------------------------------

    def _files_of(self, event_type: str) -> list[DataFile]:
        if self._files is None:
            holding = self.lake._files_holding(self._table, self.run.robot, [self.run.run])
            self._files = {t: [f for f in holding if f.kind == t] for t in self.run.rows}
        return self._files.get(event_type, [])

    def _parts(
        self, event_type: str, stream: str | None = None, rows: int = SCAN_ROWS
    ) -> Iterator[pa.Table]:
        """The run's rows of one type, as :func:`event_schema` types them, in the files' order
        (the rows of ``stream`` only, if given)."""
        files = self._files_of(event_type)
        if not files:
            return
        run = self.run
        dataset = self.lake.files_dataset(files)
        where = pc.field("type") == event_type  # each file's partition: no test a row
        if not _only_rows_of(dataset, run):
            where &= (
                (pc.field("robot") == run.robot)
                & (pc.field("run") == run.run)
                & (pc.field("commit") == run.commit)
            )
        if stream is not None:
            where &= pc.field("stream") == stream
        schema = event_schema(event_type, self.lake.store)
        payload_names = [n for n in schema.names if n not in _ENVELOPE]
        scanner = dataset.scanner(
            columns=[*_ENVELOPE, event_type],
            filter=where,
            batch_size=rows,
            batch_readahead=1,
            fragment_readahead=1,
            use_threads=False,
            fragment_scan_options=pds.ParquetFragmentScanOptions(pre_buffer=False),
            # The system's allocator, not Arrow's default (mimalloc): mimalloc kept the pages
            # of every batch read (a where from a lake run of 1 M events grew by ~170 MB of
            # resident memory with 20 MB of Arrow's allocated).
            memory_pool=pa.system_memory_pool(),
        )
        for batch in scanner.to_batches():
            if not batch.num_rows:
                continue
            payload = batch.column(event_type)
            columns = [batch.column(n) for n in _ENVELOPE]
            columns += [payload.field(n) for n in payload_names]
            yield pa.Table.from_arrays(columns, names=schema.names).cast(schema)

    def _sorted_parts(
        self, event_type: str, stream: str | None = None, rows: int = SCAN_ROWS
    ) -> Iterator[pa.Table]:
        if event_type not in self._unsorted:
            yield from self._parts(event_type, stream, rows)
            return
        parts = list(self._parts(event_type, stream, rows))
        if parts:
            yield pa.concat_tables(parts).sort_by("seq")

    def _read_error(self, exc: BaseException) -> Exception:
        run = self.run
        return TableLakeError(
            f"{self.lake.root}: run {run.robot}/{run.run} could not be read: {exc}"
        )

    def _damaged(self, rows: dict[str, int]) -> Exception:
        run = self.run
        return TableLakeError(
            f"{self.lake.root}: run {run.robot}/{run.run} is damaged: its rows do not read back "
            f"as committed (rows {rows}, committed {dict(run.rows)}); `objsearch lake verify "
            f"{self.lake.root}` names the files"
        )

    # -- the two reads ------------------------------------------------------------------------

    def check(self) -> None:
        """Read every row of the run and compare it with what its commit recorded (rows per
        type, digest); raises :class:`TableLakeError` if they differ or a file does not read."""
        if self._checked:
            return
        if digest_version(self.run.digest) != 2:
            events = self.lake.read_events(self.run, self._table)
            self._whole = events
            streams: dict[str, set[str]] = {}
            for e in events:
                streams.setdefault(e.type, set()).add(e.stream)
            self.streams = {t: frozenset(s) for t, s in streams.items()}
            self._checked = True
            return
        digests: dict[str, str] = {}
        rows: dict[str, int] = {}
        try:
            self._checked_files = self._identities()
            for event_type in sorted(self.run.rows):
                digest, rows[event_type], streams_of = self._check_type(event_type)
                if digest is None:  # out of seq order in the files: read whole, sorted
                    self._unsorted.add(event_type)
                    digest, rows[event_type], streams_of = self._check_type(event_type)
                assert digest is not None
                digests[event_type] = digest
                self.streams[event_type] = streams_of
        except (OSError, pa.ArrowException) as exc:
            raise self._read_error(exc) from exc
        if rows != dict(self.run.rows) or DIGEST_PREFIX + combine(digests) != self.run.digest:
            raise self._damaged(rows)
        self._checked = True
        # What the check's reads freed back to the system before the events are read (Arrow's
        # default pool keeps freed pages for reuse otherwise: ~20 MB at 1 M events).
        pa.default_memory_pool().release_unused()

    def _check_type(self, event_type: str) -> tuple[str | None, int, frozenset[str]]:
        """The type's digest (None if its rows are not in seq order), rows and streams."""
        digest = TypeDigest(gather=0)
        rows = 0
        streams: set[str] = set()
        last: int | None = None
        for part in self._sorted_parts(event_type, rows=CHECK_ROWS):
            seq = part.column("seq").to_numpy()
            if (last is not None and seq[0] < last) or bool((np.diff(seq) < 0).any()):
                return None, 0, frozenset()
            last = int(seq[-1])
            digest.add(part)
            rows += part.num_rows
            streams.update(pc.unique(part.column("stream")).to_pylist())
        return digest.hexdigest(), rows, frozenset(streams)

    def events(self, streams: Collection[str] | None = None) -> Iterator[Event]:
        """The run's events (of ``streams`` only, if given), upcast, sorted by (stream, seq) as
        :meth:`TableLake.read_events` sorts them; :meth:`check` first if it has not run."""
        self.check()
        if self._whole is not None:
            upcast = self.lake.store.upcaster.upcast
            for e in self._whole:
                if streams is None or e.stream in streams:
                    yield upcast(e)
            return
        every = sorted(set().union(*self.streams.values())) if self.streams else []
        wanted = [s for s in every if streams is None or s in streams]
        whole = len(every) == 1  # no stream to pick rows by
        try:
            for stream in wanted:
                types = [t for t in sorted(self.run.rows) if stream in self.streams.get(t, ())]
                # A type of a few rows (run_started, scene_graph_seeded) is read at once, so
                # only the long ones keep a reader open through the merge.
                merged = _merge_by_seq(
                    [
                        iter(list(self._events_of(t, None if whole else stream)))
                        if self.run.rows[t] <= EVENT_ROWS
                        else self._events_of(t, None if whole else stream)
                        for t in types
                    ]
                )
                for events in merged:
                    yield from events
            changed = self._identities() != self._checked_files
        except (OSError, pa.ArrowException) as exc:
            raise self._read_error(exc) from exc
        if changed:
            raise TableLakeError(
                f"{self.lake.root}: run {self.run.robot}/{self.run.run} changed while it was "
                "read (a file of it was written to between the check and the read); read it "
                f"again, and `objsearch lake verify {self.lake.root}` names damaged files"
            )

    def _identities(self) -> dict[str, tuple[int, int, int, int]] | None:
        """Each local file's size, mtime, ctime and inode (None on an object store, whose
        objects are not rewritten in place): any write to a file changes its ctime."""
        if self.lake.remote:
            return None
        out = {}
        for event_type in sorted(self.run.rows):
            for f in self._files_of(event_type):
                st = os.stat(Path(self.lake.uri) / f.path)
                out[f.path] = (st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino)
        return out

    def _events_of(self, event_type: str, stream: str | None) -> Iterator[list[Event]]:
        """The type's events, upcast, in seq order, a slice of up to :data:`EVENT_ROWS` at a
        time (none empty)."""
        store = self.lake.store
        upcast = store.upcaster.upcast
        latest = store.upcaster.latest_version(event_type)
        for part in self._sorted_parts(event_type, stream):
            for start in range(0, part.num_rows, EVENT_ROWS):
                rows = part.slice(start, EVENT_ROWS)
                # Each event's record converted with its slice and kept on its payload
                # (:class:`~objsearch.events.envelope.ReadPayload`, as a log's event keeps the
                # one a fold decodes): ``where`` folds each event into four projections, which
                # converted a lake payload's dict 2.4 times an event.
                with _no_collection():
                    events = tables_to_events([rows], store, records=True)
                if latest is not None and pc.min(rows.column("version")).as_py() < latest:
                    events = [upcast(e) for e in events]
                if events:
                    yield events


def _only_rows_of(dataset: pds.Dataset, run: TableRun) -> bool:
    """Whether every row group of ``dataset``'s files says, in its statistics, that it holds
    rows of ``run`` only (its robot, run and commit, none null), as every file a commit of this
    module writes does: then no row need be tested against them (that test was ~45 % of a
    scan's CPU). A file whose statistics lie can only add rows that the run's check counts and
    hashes (refused as damaged), never hide one; a file of several runs (delta-rs's compaction)
    or without statistics is filtered row by row, as before."""
    wanted = {"robot": run.robot, "run": run.run, "commit": run.commit}
    for fragment in dataset.get_fragments():
        metadata = fragment.metadata
        leaves = {metadata.schema.column(i).path: i for i in range(len(metadata.schema))}
        if any(name not in leaves for name in wanted):
            return False
        for group in range(metadata.num_row_groups):
            row_group = metadata.row_group(group)
            if not row_group.num_rows:  # no row to test (and no statistics to say so)
                continue
            for name, value in wanted.items():
                stats = row_group.column(leaves[name]).statistics
                if (
                    stats is None
                    or not stats.has_min_max
                    or not stats.has_null_count
                    or stats.null_count != 0
                    or stats.min != value
                    or stats.max != value
                ):
                    return False
    return True


_SEQ: Final = operator.attrgetter("seq")


@contextlib.contextmanager
def _no_collection() -> Iterator[None]:
    """No cyclic garbage collection inside (then as before): building a slice's events makes
    ~6 containers a row that live on, so the collector ran ~8 times a slice, each a walk of the
    young objects, and the full collections those promote walked every object of the process:
    a ``where`` from a run of 1 M events spent 2.5 CPU-s collecting (8,930 young, 73 full
    collections), and 0.8 with this (937 young, one a slice; 7 full)."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def _merge_by_seq(sources: list[Iterator[list[Event]]]) -> Iterator[list[Event]]:
    """The events of ``sources`` (each its events in seq order, in lists) in seq order, a list
    at a time, with no Python step an event (:func:`heapq.merge` took one, with a key call, per
    event): each round hands out every pending event up to the least of the sources' last
    pending seqs, sorted (stably: equal seqs, which one stream does not hold, in the sources'
    order within a round)."""
    pending: list[tuple[Iterator[list[Event]], list[Event]]] = []
    for source in sources:
        first = _next_events(source)
        if first:
            pending.append((source, first))
    while pending:
        bound = min(events[-1].seq for _, events in pending)
        out: list[Event] = []
        parts = 0
        kept: list[tuple[Iterator[list[Event]], list[Event]]] = []
        for source, events in pending:
            cut = bisect.bisect_right(events, bound, key=_SEQ)
            if cut:
                out += events[:cut] if cut < len(events) else events
                parts += 1
            rest = events[cut:] if cut < len(events) else _next_events(source)
            if rest:
                kept.append((source, rest))
        pending = kept
        if parts > 1:
            out.sort(key=_SEQ)
        yield out


def _next_events(source: Iterator[list[Event]]) -> list[Event] | None:
    """The next list of ``source`` that holds an event (None at its end)."""
    for events in source:
        if events:
            return events
    return None


__all__ = ["CHECK_ROWS", "EVENT_ROWS", "SCAN_ROWS", "RunReader"]
