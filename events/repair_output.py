"""The repaired ``events.log`` as :mod:`.repair_plan` builds it, record by record (:class:`Plan`),
and what the repair did at each place of the damaged file (:class:`RepairAction`)."""

from __future__ import annotations

import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Final

from .envelope import EVENT_ID_NAMESPACE, Event
from .log_files import LogMeta
from .record import encode_record
from .scan import QUARANTINED_TYPE, _Cursor


@dataclass(frozen=True, slots=True)
class RepairAction:
    """One thing :func:`~objsearch.events.repair.repair_log` did, at one place of the original
    file."""

    #: "checksum-rewritten", "bit-restored", "byte-restored", "line-ending-restored",
    #: "reordered", "quarantined", "extra", "lost", "cut", "missing"
    kind: str
    first_seq: int  # the seq(s) it concerns
    last_seq: int
    line: int  # line (1-based) and byte offset in the file as it was (the end, for "missing")
    offset: int
    reason: str


#: The kinds that keep or account for a record by a witness (not a cut or a loss).
PROVEN_KINDS: Final = frozenset(
    {
        "checksum-rewritten",
        "bit-restored",
        "line-ending-restored",
        "byte-restored",
        "reordered",
        "quarantined",
        "lost",
    }
)


@dataclass(slots=True)
class _Keep:
    """A record restored from the damaged file (its bytes changed back)."""

    index: int | None  # the original line (None: the fragment after the last newline)
    line: bytes  # what the repaired file holds (without its newline)
    seq: int
    time_ns: int
    real: bool  # an event, not a record_quarantined marker of an earlier repair
    chain: int


@dataclass(slots=True)
class _Run:
    """Consecutive lines ``start..stop - 1`` kept as they are, seqs ``first_seq`` on."""

    start: int
    stop: int
    first_seq: int
    real: int  # events among them (markers of an earlier repair not counted)
    seq: int  # the last one's seq, time and chain value
    time_ns: int
    chain: int


@dataclass(slots=True)
class _Marker:
    reason: str
    refs: tuple[int, ...]  # the removed lines it stands for (-1: the unterminated fragment)
    chain: int | None


@dataclass
class Plan:
    """The repaired file, built record by record."""

    meta: LogMeta
    wall_clock: Callable[[], int]
    quarantine_name: str = ""
    at: _Cursor = field(default_factory=_Cursor)
    lines: list[bytes] = field(default_factory=list)  # the new file's lines, newlines included
    removed: bytearray = field(default_factory=bytearray)
    actions: list[RepairAction] = field(default_factory=list)
    events: int = 0  # real events kept (markers not counted)
    kept_records: int = 0  # lines of the damaged file kept (as they were, or restored)
    missing: tuple[int, int] | None = None
    mark_chain: int | None = None  # the chain value at the durable mark, if nothing before it
    #: changed and every record up to it verified as it stands

    @property
    def clean(self) -> bool:
        return not self.actions and not self.removed

    def actions_before_cut(self) -> bool:
        return any(a.kind in PROVEN_KINDS for a in self.actions)

    def keep(self, line: bytes, seq: int, time_ns: int, chain: int, *, real: bool) -> None:
        self.lines.append(line + b"\n")
        at = self.at
        at.offset += len(line) + 1
        at.line += 1
        at.seq = seq
        at.checksum = chain
        at.time_ns = time_ns
        self.events += real

    def keep_run(self, lines: list[bytes], run: _Run) -> None:
        """:meth:`keep` of lines kept as they are, in one go."""
        start = len(self.lines)
        self.lines.extend(line + b"\n" for line in lines)
        at = self.at
        at.offset += sum(len(line) for line in self.lines[start:])
        at.line += len(lines)
        at.seq, at.checksum, at.time_ns = run.seq, run.chain, run.time_ns
        self.events += run.real
        self.kept_records += len(lines)

    def marker(
        self, *, reason: str, offset: int, length: int, chain: int | None, kept: bool
    ) -> None:
        """A ``record_quarantined`` event at the next seq."""
        at = self.at
        seq = at.seq + 1
        event = Event(
            event_id=str(uuid.uuid5(EVENT_ID_NAMESPACE, f"{self.meta.id_key()}/{seq}/quarantined")),
            stream=self.meta.stream,
            seq=seq,
            time_ns=at.time_ns,
            recorded_at_ns=self.wall_clock(),
            type=QUARANTINED_TYPE,
            version=1,
            task_id=None,
            payload={
                "reason": reason,
                "quarantine": self.quarantine_name if kept else None,
                "offset": offset,
                "length": length,
                "chain": None if chain is None else f"{chain:08x}",
            },
        )
        line = encode_record(event, at.checksum if self.meta.chained else 0)[:-1]
        own = int(line[-8:], 16)
        self.keep(line, seq, at.time_ns, own if chain is None else chain, real=False)

    def output(self) -> bytes:
        return b"".join(self.lines)
