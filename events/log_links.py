"""Links between the lines of a chained log: every intact record names the chain value it was
written after, so it can be recognised wherever it stands, whatever damage came before it.

A record's checksum is CRC-32 of its bytes started from its predecessor's chain value. CRC-32 is
affine in that start value: for ``n`` bytes, ``crc32(b, p) == T_n(p) ^ crc32(b, 0)`` with ``T_n``
linear and invertible (it only depends on ``n``). So a record's own bytes and checksum give the
value it was chained from (:func:`chained_from`), and two lines *link* when one's checksum is the
value the other was chained from: a 2⁻³² coincidence for anything but the record its writer
wrote after it. ``objsearch log repair`` walks these links (:mod:`.repair_plan`) instead of the
lines' order, so a blank or duplicated line, lines swapped or a damaged record costs no intact
record after it.

Also here: :func:`meta_mismatch`, which tells an edited ``meta.json`` from a damaged first
record by the same witnesses (the first record's chain start, its successor, the durable mark).
"""

from __future__ import annotations

import functools
import itertools
import zlib
from collections.abc import Callable
from typing import Final, NamedTuple

import msgspec

from .envelope import deterministic_event_id
from .log_files import LOG_FORMAT, LOG_FORMAT_V1, LogMeta
from .record import RECORD_SEPARATOR


@functools.lru_cache(maxsize=8192)
def _inverse(length: int) -> tuple[int, ...]:
    """Column ``k``: the start value ``p`` with ``T_length(p) == 1 << k`` (``T_length`` as in the
    module docstring), by Gauss-Jordan elimination over GF(2)."""
    zeros = bytes(length)
    base = zlib.crc32(zeros, 0)
    # (T(x), x) for the unit vectors x; row operations keep "value == T(combination)".
    rows = [(zlib.crc32(zeros, 1 << k) ^ base, 1 << k) for k in range(32)]
    for bit in range(32):
        pivot = next(i for i in range(bit, 32) if rows[i][0] >> bit & 1)  # T is invertible
        rows[bit], rows[pivot] = rows[pivot], rows[bit]
        value, combination = rows[bit]
        for i in range(32):
            if i != bit and rows[i][0] >> bit & 1:
                rows[i] = (rows[i][0] ^ value, rows[i][1] ^ combination)
    return tuple(combination for _, combination in rows)


def chained_from(body: bytes, checksum: int) -> int:
    """The start value ``p`` with ``zlib.crc32(body, p) == checksum``: what the record before
    ``body`` ended its chain with, if ``body`` and ``checksum`` are as their writer wrote them."""
    columns = _inverse(len(body))
    target = checksum ^ zlib.crc32(body, 0)
    value = 0
    k = 0
    while target:
        if target & 1:
            value ^= columns[k]
        target >>= 1
        k += 1
    return value


class _Head(msgspec.Struct, forbid_unknown_fields=False):
    """The envelope fields a line is placed by (the rest is checked when it is kept)."""

    event_id: str = ""
    stream: str = ""
    seq: int = 0


_decode_head: Final = msgspec.json.Decoder(_Head).decode


class LineInfo(NamedTuple):
    """What one line of ``events.log`` says about where it belongs, read without trusting it
    (a tuple: one is made for every line after a break in a long log)."""

    body: bytes
    checksum: int | None  # the stored checksum, if it is 8 lower-case hex digits after a tab
    chained_from: int | None  # the value the checksum was chained from (None: no checksum)
    seq: int | None  # the envelope's seq, stream and id, if the JSON gives them
    stream: str | None
    event_id: str | None

    def own(self, meta: LogMeta) -> bool:
        """It carries this log's default id for its seq (an id derived from ``meta``'s run)."""
        return (
            self.seq is not None
            and self.seq > 0
            and self.stream == meta.stream
            and self.event_id == deterministic_event_id(meta.id_key(), self.seq)
        )


def line_info(line: bytes) -> LineInfo:
    """:class:`LineInfo` of ``line`` (without its newline); never raises."""
    body, sep, crc = line.rpartition(RECORD_SEPARATOR)
    if not sep:
        body = line
    checksum = None
    if sep and len(crc) == 8:
        try:
            value = int(crc, 16)
        except ValueError:
            value = -1
        if value >= 0 and crc == b"%08x" % value:
            checksum = value
    seq = stream = event_id = None
    try:
        head = _decode_head(body)
    except (msgspec.MsgspecError, ValueError):
        pass
    else:
        if head.seq > 0 and head.stream:
            seq, stream, event_id = head.seq, head.stream, head.event_id
    return LineInfo(
        body,
        checksum,
        None if checksum is None else chained_from(body, checksum),
        seq,
        stream,
        event_id,
    )


#: How many lines from the start :func:`meta_mismatch` reads (within its first MiB).
_META_WINDOW: Final = 16


def meta_mismatch(prefix: Callable[[int], bytes], meta: LogMeta) -> str | None:
    """Why ``meta.json`` cannot be the one the records were written under — or None when no
    witness proves it (the first record verifies, or may just be damaged itself).
    ``prefix(n)``: the first ``n`` bytes of ``events.log`` (fewer if it is shorter).

    Witnesses, none of which trusts the first record: the stream every record carries; records
    that link to their predecessors (chained: not format 1) or carry plain checksums (format 1,
    not 2); records intact by their links of which none carries an id derived from
    ``meta.json``'s run id. (Not the seals: solved for the start value of their CRC, they make a
    first record damaged in its bytes alone verify too.)"""
    lines = prefix(1 << 20).split(b"\n")[:-1][:_META_WINDOW]
    infos = [line_info(line) for line in lines]
    records = [i for i in infos if i.seq is not None]
    if not records:
        return None
    said = f"meta.json says {meta.format!r}, stream {meta.stream!r}, run id {meta.run_id}"
    restore = "restore the meta.json this log was written with"
    streams = {i.stream for i in records}
    if meta.stream not in streams:
        found = sorted(s for s in streams if s)[0]
        return (
            f"the records are of stream {found!r}, but {said}: meta.json was edited or "
            f"replaced, or events.log is another log's; {restore}"
        )
    first = infos[0]
    if first.checksum is not None and (
        zlib.crc32(first.body, meta.genesis if meta.chained else 0) == first.checksum
    ):
        return None  # the first record verifies under this meta.json
    # Line i is intact and chained from line i - 1 (a format-1 record would link only to a
    # predecessor whose checksum is 0).
    linked = [
        b
        for a, b in itertools.pairwise(infos)
        if a.checksum is not None
        and b.chained_from == a.checksum
        and a.seq is not None
        and b.seq == a.seq + 1
    ]
    plain = [i for i in infos if i.checksum is not None and zlib.crc32(i.body) == i.checksum]
    if not meta.chained:
        if linked:
            return (
                f"the records are chained ({LOG_FORMAT!r}: each record's checksum starts from "
                f"its predecessor's), but {said}: meta.json was edited (its format, or its run "
                f"id removed); {restore}"
            )
        return None
    if len(plain) >= 2:
        return (
            f"the records carry plain checksums ({LOG_FORMAT_V1!r}), but {said}: meta.json was "
            f"edited or replaced; {restore}"
        )
    if len(linked) >= 2 and not any(i.own(meta) for i in records):
        return (
            f"{len(linked) + 1} records verify among themselves, but neither the first "
            f"record's checksum nor any record's id derives from meta.json ({said}): meta.json "
            "was edited or replaced (its stream or run id) — or every record carries an id of "
            f"its own and the first one is damaged; {restore}, or compare with a copy"
        )
    return None
