"""What ``objsearch log repair`` keeps: the records of a damaged ``events.log``, found by their
witnesses rather than by where they stand.

The plan walks the file in order while each line is the next valid record. Where one is not, it
looks for the record that *is* next: the line whose checksum was chained from the last kept one
(:mod:`.log_links`), wherever it stands — so a blank, duplicated, inserted or moved line costs
no record after it, and records out of order are put back in their order. When no line links,
the damage is judged in place, each repair proven by a witness: a line ending in CR restored;
a flipped bit (in the record, its tab or its newline: CRC-32 names it, the result must verify);
checksum digits rewritten (proven by the next record, the high-water mark, or the damaged
digits being one bit or a cut away from the right ones); a damaged record whose own checksum the
next record proves is replaced by a ``record_quarantined`` event that carries its chain on. When
nothing there can be proven, the next intact record of this log (its own id at a later seq,
its checksum proven by its successor) resumes the log, the chain value it was written after
solved from its own bytes, and ``record_quarantined`` events hold the seqs in between. What no
witness places is moved out; every byte taken out is kept in the quarantine file.
"""

from __future__ import annotations

import bisect
import collections
import zlib
from collections.abc import Callable, Iterable, Iterator
from typing import Final

from .diagnose import single_bit_error
from .envelope import Event, deterministic_event_id
from .log_files import Durable, LogMeta
from .log_links import LineInfo, line_info
from .repair_output import Plan, RepairAction, _Keep, _Marker, _Run
from .scan import QUARANTINED_TYPE, BadRecord, _Cursor, check_record
from .schemas import SchemaRegistry

#: The bytes one flipped bit away from a newline (and from a tab).
_NEAR_NEWLINE: Final = frozenset(0x0A ^ (1 << b) for b in range(8))
_NEAR_TAB: Final = frozenset(0x09 ^ (1 << b) for b in range(8))
#: How many unused lines after the last kept one are judged in place at a break.
_WINDOW: Final = 3
#: How many lines from a break are searched for the next record before every line after the
#: first break is indexed.
_NEAR: Final = 64


def plan_repair(
    data: bytes,
    meta: LogMeta,
    durable: Durable | None,
    registry: SchemaRegistry,
    wall_clock: Callable[[], int],
    quarantine_name: Callable[[int], str],
    progress: Callable[[Iterable[int]], Iterable[int]],
) -> Plan:
    """The repair of ``data`` (all of ``events.log``): what is kept, restored, marked and moved
    out. ``quarantine_name(offset)`` names the file the removed bytes go to (``offset``: where
    the first of them was); ``progress`` wraps the walk (one item per step)."""
    walk = _Walk(data, meta, durable, registry)
    collections.deque(progress(walk.steps()), maxlen=0)
    return walk.emit(wall_clock, quarantine_name)


class _Walk:
    """Which line holds each seq, decided in order (:meth:`steps`), then written (:meth:`emit`)."""

    def __init__(
        self, data: bytes, meta: LogMeta, durable: Durable | None, registry: SchemaRegistry
    ) -> None:
        lines = data.split(b"\n")
        self.tail = lines.pop()  # the unterminated fragment after the last newline (b"" if none)
        self.lines = lines
        self.offsets = [0]
        for line in lines:
            self.offsets.append(self.offsets[-1] + len(line) + 1)
        self.meta = meta
        self.durable = durable
        self.registry = registry
        self.at = _Cursor(checksum=meta.genesis)
        self.slots: list[_Run | _Keep | _Marker] = []
        self.actions: list[RepairAction] = []
        # 0: not used; 1: kept as it is; 2: taken out, its record restored or marked
        self.used = bytearray(len(lines))
        self.last = -1  # the furthest line (index) kept or taken
        self.prev = -1  # the line the last kept record came from
        self.resynced = False  # a line was not the next record (the plan is not plain reading)
        self.first_break = 0  # the first such line
        self.explained: set[int] = set()  # lines a marker stands for
        self.tail_used = False
        self.mark_chain: int | None = None
        self._infos: list[LineInfo | None] = [None] * len(lines)
        self._links: dict[tuple[int, int], list[int]] | None = None
        self._by_seq: dict[int, list[int]] = {}
        self._seqs: list[int] = []

    # -- deciding -------------------------------------------------------------------------

    def steps(self) -> Iterator[int]:
        lines = self.lines
        n = len(lines)
        used = self.used
        p = 0
        while True:
            while p < n and used[p]:
                p += 1
            if p < n and self._take(p):
                p += 1
                yield p
                continue
            resumed = self._resync(p)
            if resumed is None:
                break
            p = resumed
            yield p
        self._finish()

    def _check(self, line: bytes, at: _Cursor) -> tuple[Event, int] | None:
        try:
            return check_record(line, at, self.meta, self.registry)
        except BadRecord:
            return None

    def _take(self, i: int) -> bool:
        """Keep line ``i`` as it is if it is the next valid record."""
        found = self._check(self.lines[i], self.at)
        if found is None:
            return False
        event, chain = found
        if i < self.prev:
            why = (
                f"out of order: it stands before line {self.prev + 1}, the record of seq "
                f"{self.at.seq}, whose checksum its own was chained from; put back after it"
            )
            self._act("reordered", event.seq, event.seq, i, why)
        self._keep(i, self.lines[i], event, chain, verbatim=True)
        mark = self.durable
        if mark is not None and event.seq == mark.seq and not self.actions and not self.resynced:
            self.mark_chain = chain
        return True

    def _keep(
        self, i: int | None, line: bytes, event: Event, chain: int, *, verbatim: bool
    ) -> None:
        real = event.type != QUARANTINED_TYPE
        slots = self.slots
        if not verbatim:
            slots.append(_Keep(i, line, event.seq, event.time_ns, real, chain))
        else:
            assert i is not None
            run = slots[-1] if slots else None
            if isinstance(run, _Run) and run.stop == i:
                run.stop += 1
                run.real += real
                run.seq, run.time_ns, run.chain = event.seq, event.time_ns, chain
            else:
                slots.append(_Run(i, i + 1, event.seq, real, event.seq, event.time_ns, chain))
        if i is not None:
            self.used[i] = 1 if verbatim else 2
            self.last = max(self.last, i)
            self.prev = i
        at = self.at
        at.seq, at.checksum, at.time_ns = event.seq, chain, event.time_ns

    def _mark(self, reason: str, refs: tuple[int, ...], chain: int | None) -> None:
        self.slots.append(_Marker(reason, refs, chain))
        self.at.seq += 1
        if chain is not None:
            self.at.checksum = chain
        self.explained.update(refs)

    def _act(self, kind: str, first: int, last: int, i: int, reason: str) -> None:
        offset = self.offsets[i] if i >= 0 else self.offsets[-1]
        line = i + 1 if i >= 0 else len(self.lines) + 1
        self.actions.append(RepairAction(kind, first, last, line, offset, reason))

    def _info(self, i: int) -> LineInfo:
        info = self._infos[i]
        if info is None:
            info = self._infos[i] = line_info(self.lines[i])
        return info

    def _index(self) -> dict[tuple[int, int], list[int]]:
        """Every line not yet placed, from the first that was not the next record, by (the chain
        value it was written after, its seq); built only when nearby lines do not settle it."""
        if self._links is None:
            links: dict[tuple[int, int], list[int]] = {}
            by_seq = self._by_seq
            used = self.used
            for i in range(self.first_break, len(self.lines)):
                if used[i]:
                    continue  # placed for good: never looked up again
                info = self._info(i)
                if info.seq is None:
                    continue
                by_seq.setdefault(info.seq, []).append(i)
                if info.chained_from is not None:
                    links.setdefault((info.chained_from, info.seq), []).append(i)
            self._links = links
            self._seqs = sorted(by_seq)
        return self._links

    def _cursor(self, seq: int, chain: int, time_ns: int) -> _Cursor:
        return _Cursor(seq=seq, checksum=chain, time_ns=time_ns)

    def _chained(self, chain: int, seq: int, near: int) -> Iterator[int]:
        """The unused lines of ``seq`` written after ``chain``: first those among the
        :data:`_NEAR` lines from ``near``, then (the index built) any other."""
        key = (chain, seq)
        end = min(len(self.lines), near + _NEAR)
        for j in range(max(near, 0), end):
            if not self.used[j]:
                info = self._info(j)
                if (info.chained_from, info.seq) == key:
                    yield j
        for j in self._index().get(key, ()):
            if not (near <= j < end) and not self.used[j]:
                yield j

    def _proves(self, chain: int, seq: int, time_ns: int, near: int) -> bool:
        """A witness that the record of ``seq - 1`` ended the chain with ``chain``: an unused
        line of ``seq`` chained from it (looked for from line ``near`` first), or the mark."""
        mark = self.durable
        if mark is not None and mark.seq == seq - 1 and mark.checksum == chain:
            return True
        if not self.meta.chained:
            return False  # format 1: a record proves nothing about its neighbour
        at = self._cursor(seq - 1, chain, time_ns)
        return any(
            self._check(self.lines[j], at) is not None for j in self._chained(chain, seq, near)
        )

    def _resync(self, p: int) -> int | None:
        """At a line that is not the next record: the physical line to go on from, having kept
        or marked the next seq(s); None when nothing more can be proven. Nearby lines first:
        most damage is one place, and a long log's index is built only when they do not do."""
        if not self.resynced:
            self.resynced = True
            self.first_break = p
        if self.used.find(0, self.first_break) < 0:
            return None  # every line is placed
        at = self.at
        key = (at.checksum if self.meta.chained else 0, at.seq + 1)
        end = min(len(self.lines), p + _NEAR)
        for j in range(p, end):
            info = None if self.used[j] else self._info(j)
            if info is not None and (info.chained_from, info.seq) == key and self._take(j):
                return j + 1
        candidates = self._window(p)
        for j in candidates:
            resumed = self._restore(j)
            if resumed is not None:
                return resumed
        for j in self._index().get(key, ()):
            if not self.used[j] and self._take(j):
                return j + 1
        for j in self._by_seq.get(at.seq + 1, ()):
            if not self.used[j] and j not in candidates:
                candidates.append(j)
                resumed = self._restore(j)
                if resumed is not None:
                    return resumed
        for j in candidates:
            resumed = self._quarantine(j)
            if resumed is not None:
                return resumed
        return self._head()

    def _window(self, p: int) -> list[int]:
        out: list[int] = []
        j = p
        while j < len(self.lines) and len(out) < _WINDOW:
            if not self.used[j] and self.lines[j].strip():
                out.append(j)
            j += 1
        return out

    # -- judging a line in place ------------------------------------------------------------

    def _restore(self, i: int) -> int | None:
        """Restore the record of the next seq, exactly as written, from line ``i`` if a witness
        proves how; the physical line to go on from."""
        line = self.lines[i]
        at = self.at
        seq = at.seq + 1
        if line.endswith(b"\r"):
            found = self._check(line[:-1], at)
            if found is not None:
                self._restored(
                    i, line[:-1], found, "line-ending-restored", "a CR before its newline"
                )
                return i + 1
        if len(line) >= 9 and line[-9] in _NEAR_TAB:
            fixed = line[:-9] + b"\t" + line[-8:]
            found = self._check(fixed, at)
            if found is not None:
                self._restored(i, fixed, found, "bit-restored", "one flipped bit in its tab")
                return i + 1
        resumed = self._split(i) or self._join(i)
        if resumed is not None:
            return resumed
        info = self._info(i)
        body, sep, stored = line.rpartition(b"\t")
        if not sep:
            return None
        prev = at.checksum if self.meta.chained else 0
        computed = zlib.crc32(body, prev)
        if info.checksum is not None:
            flipped = single_bit_error(computed ^ info.checksum, len(body))
            if flipped is not None:
                index, bit = flipped
                fixed_body = bytearray(body)
                fixed_body[index] ^= 1 << bit
                fixed = bytes(fixed_body) + sep + stored
                found = self._check(fixed, at)
                if found is not None and (
                    found[0].event_id == deterministic_event_id(self.meta.id_key(), seq)
                    or self._proves(info.checksum, seq + 1, found[0].time_ns, i + 1)
                ):
                    why = f"one flipped bit (byte {index} of the record, bit {bit})"
                    self._restored(i, fixed, found, "bit-restored", why)
                    return i + 1
        right = b"%08x" % computed
        fixed = body + sep + right
        found = self._check(fixed, at)
        if found is not None and (
            _one_bit_off(stored, right)
            or (4 <= len(stored) < 8 and right.startswith(stored))
            or self._proves(computed, seq + 1, found[0].time_ns, i + 1)
        ):
            self._restored(
                i,
                fixed,
                found,
                "checksum-rewritten",
                "its checksum digits were damaged; the record itself is intact (its bytes chain "
                "into the next record, or the damaged digits are one bit or a cut away)",
            )
            return i + 1
        return None

    def _quarantine(self, i: int) -> int | None:
        """Replace line ``i`` by a marker at the next seq if its own checksum is proven the one
        its writer wrote there (its bytes are not)."""
        info = self._info(i)
        seq = self.at.seq + 1
        if info.checksum is not None and self._damaged_in_place(i, info, seq):
            self._act(
                "quarantined",
                seq,
                seq,
                i,
                "its bytes were damaged (or edited): they no longer match its checksum, which "
                "the next record (or the high-water mark) proves is the one its writer wrote",
            )
            self.used[i] = 2
            self.last = max(self.last, i)
            self._mark("damaged: its bytes no longer match its checksum", (i,), info.checksum)
            return i + 1
        return None

    def _damaged_in_place(self, i: int, info: LineInfo, seq: int) -> bool:
        """Line ``i``'s own checksum is proven the one its writer wrote at ``seq`` (by its
        successor or the mark), and the line or its witness is this log's."""
        assert info.checksum is not None
        if not self.meta.chained:
            return False
        mark = self.durable
        if mark is not None and mark.seq == seq and mark.checksum == info.checksum:
            return True
        at = self._cursor(seq, info.checksum, self.at.time_ns)
        for j in self._chained(info.checksum, seq + 1, i + 1):
            if j == i:
                continue
            found = self._check(self.lines[j], at)
            if found is not None and (info.own(self.meta) or self._info(j).own(self.meta)):
                return True
        return False

    def _split(self, i: int) -> int | None:
        """Two records on one line: the newline between them one bit off."""
        line = self.lines[i]
        for k in range(9, len(line)):
            if line[k] in _NEAR_NEWLINE and line[k - 9] == 0x09:
                first = self._check(line[:k], self.at)
                if first is None:
                    continue
                after = self._cursor(first[0].seq, first[1], first[0].time_ns)
                second = self._check(line[k + 1 :], after)
                if second is None:
                    continue
                why = "one flipped bit in the newline between two records"
                self._restored(i, line[:k], first, "bit-restored", why)
                self._keep(i, line[k + 1 :], *second, verbatim=False)
                return i + 1
        return None

    def _join(self, i: int) -> int | None:
        """One record on two lines: a newline inserted into it, or one of its bytes overwritten
        by a newline (a flipped bit, most often). Any joined line must verify by its checksum:
        of the 257 tried, a wrong one passes by chance about once in 2²⁴ repairs."""
        j = i + 1
        if j >= len(self.lines) or self.used[j]:
            return None
        near = sorted(_NEAR_NEWLINE)
        for byte in (b"", *(bytes((b,)) for b in near), *(bytes((b,)) for b in range(256))):
            joined = self.lines[i] + byte + self.lines[j]
            found = self._check(joined, self.at)
            if found is not None:
                if not byte:
                    kind, why = "line-ending-restored", "a newline inserted into it, taken out"
                elif byte[0] in _NEAR_NEWLINE:
                    kind, why = "bit-restored", "one flipped bit had made a byte of it a newline"
                else:
                    kind, why = "byte-restored", f"a byte of it overwritten by a newline: {byte!r}"
                self._restored(i, joined, found, kind, why)
                self.used[j] = 2
                self.last = max(self.last, j)
                return j + 1
        return None

    def _restored(self, i: int, line: bytes, found: tuple[Event, int], kind: str, why: str) -> None:
        event, chain = found
        self._act(kind, event.seq, event.seq, i, why)
        self._keep(i, line, event, chain, verbatim=False)

    # -- resuming after what cannot be judged --------------------------------------------------

    def _head(self) -> int | None:
        """The next record this log's own id and a witness place (its checksum proven by its
        successor or the mark, or nothing after it), seqs between held by markers."""
        at = self.at
        self._index()
        seqs = self._seqs
        for s in seqs[bisect.bisect_right(seqs, at.seq + 1) :]:
            for j in self._by_seq[s]:
                if self.used[j]:
                    continue
                info = self._info(j)
                if info.checksum is None or info.stream != self.meta.stream:
                    continue
                start = info.chained_from if self.meta.chained else 0
                assert start is not None
                found = self._check(self.lines[j], self._cursor(s - 1, start, at.time_ns))
                if found is None or not self._placed(j, info, found):
                    continue
                if self._contradicted(j, s, start):
                    # Its checksum is proven, its bytes are not: moved out with what stood
                    # before it, its seq held by a marker that carries its chain on.
                    self._gap(j, s + 1, found[1], moved=j)
                    self.used[j] = 2
                    self.last = max(self.last, j)
                    return j + 1
                self._gap(j, s, start if self.meta.chained else None)
                self._keep(j, self.lines[j], *found, verbatim=True)
                return j + 1
        return None

    def _contradicted(self, j: int, seq: int, start: int) -> bool:
        """The line right before line ``j`` claims seq ``seq - 1`` with a checksum its writer
        could have written (not a plain CRC recomputed by hand), and the record of ``seq`` on
        line ``j`` was not chained from it: one of the two was damaged in its bytes, so the
        latter's bytes are not proven (two damaged records in a row)."""
        if not self.meta.chained:
            return False
        k = j - 1
        while k > self.last and (self.used[k] or not self.lines[k].strip()):
            k -= 1
        if k <= self.last:
            return False  # nothing stands between: lines lost, not damaged
        before = self._info(k)
        return (
            before.checksum is not None
            and before.seq == seq - 1
            and before.checksum != start
            and zlib.crc32(before.body) != before.checksum
        )

    def _placed(self, j: int, info: LineInfo, found: tuple[Event, int]) -> bool:
        event, chain = found
        if not self.meta.chained:
            return True  # format 1: a record that verifies is intact; its stream was checked
        mark = self.durable
        if mark is not None and mark.seq == event.seq and mark.checksum == chain:
            return True
        if not info.own(self.meta):
            return False
        if self._proves(chain, event.seq + 1, event.time_ns, j + 1):
            return True
        return all(not line.strip() for line in self.lines[j + 1 :]) and not self.tail

    def _gap(self, j: int, seq: int, chain: int | None, *, moved: int | None = None) -> None:
        """Markers for the seqs before the record of ``seq`` on line ``j`` (``moved``: that
        line too is moved out, its record not proven)."""
        first = self.at.seq + 1
        between = tuple(
            k for k in range(self.last + 1, j) if not self.used[k] and self.lines[k].strip()
        )
        last = seq - 1
        if moved is not None:
            between += (moved,)
            kind = "quarantined"
            why = (
                f"{_lines_named(between)}: the record of seq {last} keeps this log's id and a "
                "checksum the next record proves, but its bytes were not chained from the "
                "checksum of the line before it, which claims the seq before: two records "
                "damaged in a row, neither proven"
            )
        elif between:
            kind = "quarantined"
            why = (
                f"{_lines_named(between)} hold(s) no record that verifies here "
                f"(damaged, cut or not this log's); the record of seq {seq} after them is intact "
                "and this log's own, its predecessor's chain value solved from its own checksum"
            )
        else:
            kind = "lost"
            why = (
                f"the records of seqs {first}..{last} are missing from the file; the record of "
                f"seq {seq} is intact and this log's own, its predecessor's chain value solved "
                "from its own checksum"
            )
        self._act(kind, first, last, j, why)
        reason = f"{'damaged' if between else 'missing'}: {why}"
        while self.at.seq < last:
            self._mark(reason, between, chain if self.at.seq + 1 == last else None)

    def _finish(self) -> None:
        """The fragment after the last newline, the lines no witness placed, and acknowledged
        seqs the file no longer holds."""
        tail = self.tail
        if tail and tail[-1] in _NEAR_NEWLINE:
            found = self._check(tail[:-1], self.at)
            if found is not None:
                why = "one flipped bit in its newline"
                self._act("bit-restored", found[0].seq, found[0].seq, -1, why)
                self._keep(None, tail[:-1], *found, verbatim=False)
                self.tail_used = True
        lines = self.lines
        unused = [i for i, u in enumerate(self.used) if not u]
        kept = self._kept_lines() if unused else set()
        trailing = tuple(
            i for i in unused if i > self.last and lines[i].strip() and lines[i] not in kept
        )
        own = [
            info.seq
            for i in unused
            if (info := self._info(i)).seq is not None and info.own(self.meta)
        ]
        first = self.at.seq + 1
        last = max(self.at.seq + len(trailing), max(own, default=0))
        refs = trailing + ((-1,) if tail and not self.tail_used else ())
        if refs or last >= first:
            where = trailing[0] if trailing else -1
            why = (
                "an unterminated fragment (an interrupted append, never acknowledged)"
                if not trailing
                else "from here on no record can be proven to belong to this log (another "
                "log's records, damage no witness explains, or two damaged records in a row)"
            )
            self._act("cut", first, last, where, why)
            while self.at.seq < last:
                self._mark(f"moved out: {why}", refs, None)
            self.explained.update(refs)
        mark = self.durable
        if mark is not None and mark.seq > self.at.seq:
            self._act(
                "missing",
                self.at.seq + 1,
                mark.seq,
                -1,
                "acknowledged (below the high-water mark) but no longer in the file",
            )
            while self.at.seq < mark.seq:
                self._mark("missing: acknowledged, but the file had already lost it", (), None)
        if unused:
            self._extras(unused, kept)

    def _kept_lines(self) -> set[bytes]:
        kept: set[bytes] = set()
        for slot in self.slots:
            if isinstance(slot, _Run):
                kept.update(self.lines[slot.start : slot.stop])
            elif isinstance(slot, _Keep):
                kept.add(slot.line)
        return kept

    def _extras(self, unused: list[int], kept: set[bytes]) -> None:
        """Runs of lines moved out that no seq stood on: blank, copies, strays."""
        # (the first line of a stretch kept, its seq minus its line number)
        placed: list[tuple[int, int]] = []
        for slot in self.slots:
            if isinstance(slot, _Run):
                placed.append((slot.start, slot.first_seq - slot.start))
            elif isinstance(slot, _Keep) and slot.index is not None:
                placed.append((slot.index, slot.seq - slot.index))
        placed.sort()
        indices = [i for i, _ in placed]
        run: list[int] = []
        for i in [*unused, -2]:
            if i in self.explained:
                continue
            if run and i == run[-1] + 1:
                run.append(i)
                continue
            if run:
                lines = [self.lines[k] for k in run]
                if all(not x.strip() for x in lines):
                    what = "blank"
                elif all(x in kept or not x.strip() for x in lines):
                    what = "a copy of a record kept in its place"
                else:
                    what = "not the next record anywhere (a stray, another log's or damaged)"
                reason = f"{_lines_named((run[0], run[-1]))}: {what}"
                before = bisect.bisect_left(indices, run[0]) - 1
                seq = placed[before][1] + run[0] if before >= 0 else 1
                self._act("extra", seq, seq, run[0], reason)
            run = [i]

    # -- writing --------------------------------------------------------------------------------

    def emit(self, wall_clock: Callable[[], int], quarantine_name: Callable[[int], str]) -> Plan:
        plan = Plan(self.meta, wall_clock)
        plan.at.checksum = self.meta.genesis
        where: dict[int, tuple[int, int]] = {}
        removed = plan.removed
        first_change: int | None = None
        for i, used in enumerate(self.used):
            if used != 1:  # not kept as it is
                line = self.lines[i]
                if first_change is None:
                    first_change = self.offsets[i]
                where[i] = (len(removed), len(removed) + len(line) + 1)
                removed += line + b"\n"
        if self.tail:
            if first_change is None:
                first_change = self.offsets[-1]
            where[-1] = (len(removed), len(removed) + len(self.tail))
            removed += self.tail
        if first_change is not None:
            plan.quarantine_name = quarantine_name(first_change)
        for slot in self.slots:
            if isinstance(slot, _Run):
                plan.keep_run(self.lines[slot.start : slot.stop], slot)
                continue
            if isinstance(slot, _Keep):
                plan.keep(slot.line, slot.seq, slot.time_ns, slot.chain, real=slot.real)
                plan.kept_records += 1
                continue
            refs = [r for r in slot.refs if r in where]
            if refs:
                start, end = where[refs[0]][0], where[refs[-1]][1]
            else:
                start = end = 0
            plan.marker(
                reason=slot.reason,
                offset=start,
                length=end - start,
                chain=slot.chain if self.meta.chained else None,
                kept=bool(refs),
            )
        plan.actions = sorted(self.actions, key=lambda a: (a.first_seq, a.line))
        for action in plan.actions:
            if action.kind == "missing":
                plan.missing = (action.first_seq, action.last_seq)
        plan.mark_chain = self.mark_chain
        return plan


def _one_bit_off(stored: bytes, right: bytes) -> bool:
    if len(stored) != len(right):
        return False
    differ = [(a, b) for a, b in zip(stored, right, strict=True) if a != b]
    return len(differ) == 1 and bin(differ[0][0] ^ differ[0][1]).count("1") == 1


def _lines_named(indices: tuple[int, ...]) -> str:
    first, last = indices[0] + 1, indices[-1] + 1
    return f"line {first}" if first == last else f"lines {first}..{last}"
