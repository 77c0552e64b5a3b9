"""What a record whose checksum does not verify is: damaged in place, or out of place.

A record's checksum chains from its predecessor's, so the *next* record is a witness: it was
chained from this record's checksum as its writer wrote it. Three cases, told apart by the
witness (the next line, or for the last record the durable high-water mark):

- the next record verifies from this record's *stored* checksum: the checksum is original and
  this record's bytes were damaged (a flipped bit, an edit) — quarantine just this record;
- the next record verifies from the checksum this record's bytes *compute to*, and those bytes
  are a valid event at the expected seq: the record is intact and only its checksum digits were
  damaged — rewrite them;
- the witness proves the stored checksum and one flipped bit explains the difference (CRC-32
  locates a single-bit error): the original record is recovered exactly;
- neither: the record does not belong here (spliced, reordered, copied from another log, a line
  lost before it) or the damage spans more than one record — nothing after it can be proven.

The reader uses this to word its error (damaged vs. out of place); ``log repair`` to decide what
to keep. With no witness the record stays unproven.
"""

from __future__ import annotations

import functools
import json
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, Literal

from .envelope import Event, deterministic_event_id
from .errors import InvalidEventError
from .record import RECORD_SEPARATOR, RecordError, decode_record, record_checksum

Kind = Literal["extra", "lost", "checksum", "bit", "body", "unproven"]

_POLY: Final = 0xEDB88320  # CRC-32 (reflected), as zlib computes it
_TABLE: Final = tuple(
    functools.reduce(lambda c, _: (c >> 1) ^ (_POLY if c & 1 else 0), range(8), i)
    for i in range(256)
)


@dataclass(frozen=True, slots=True)
class Witness:
    """What proves a record's checksum: the next line, or the high-water mark at its seq."""

    next_line: bytes | None  # without its newline
    mark_checksum: int | None = None  # the durable mark's checksum, if the mark is at this record


@dataclass(frozen=True, slots=True)
class Diagnosis:
    kind: Kind
    #: the chain value the next record continues from (None if unproven)
    chain: int | None
    reason: str
    #: the record as its writer wrote it, when that could be recovered ("checksum", "bit")
    original: bytes | None = None
    #: "lost": the seq this intact record holds (the seqs before it are lost)
    found_seq: int = 0


def diagnose(
    line: bytes,
    prev: int,
    *,
    seq: int,
    stream: str,
    id_key: str,
    chained: bool,
    witness: Witness,
) -> Diagnosis:
    """Classify ``line`` (no newline), expected at ``seq`` after a record with chain ``prev``,
    whose stored checksum does not match its bytes (``id_key``: what the log's default event
    ids derive from)."""
    body, sep, _ = line.rpartition(RECORD_SEPARATOR)
    stored = record_checksum(line)
    if not sep:
        return Diagnosis("unproven", None, "")
    if not chained:
        # Format 1: each record is checked alone, so a neighbour proves nothing about it.
        return Diagnosis(
            "body", None, "its bytes do not match its checksum (a flipped bit or an edit)"
        )
    computed = zlib.crc32(body, prev)

    def proves(value: int, *, expect: int = seq + 1) -> bool:
        return _proves(witness, stream, value, expect)

    # Not a record of this place at all: the next line continues the chain from the previous
    # record, as if this line were not there (a duplicated or inserted line).
    if witness.next_line is not None and proves(prev, expect=seq):
        return Diagnosis(
            "extra",
            prev,
            "a line out of place (duplicated, inserted or moved): the next record continues "
            "the chain from the record before it",
        )

    event = _event_of(body)
    if (
        event is not None
        and event.stream == stream
        and event.seq > seq
        and event.event_id == deterministic_event_id(id_key, event.seq)
    ):
        # This log's own record of a later seq: the lines before it were lost. Its checksum
        # chains from its lost predecessor's, which CRC-32's linearity recovers from it.
        before = chain_before(body, stored) if stored is not None else None
        if before is not None and (
            witness.next_line is None or proves(stored or 0, expect=event.seq + 1)
        ):
            return Diagnosis(
                "lost",
                before,
                f"the records of seqs {seq}..{event.seq - 1} before it are missing from the "
                f"file; this one (seq {event.seq}) is intact and this log's own",
                found_seq=event.seq,
            )
    if _belongs(event, seq, stream) and proves(computed):
        return Diagnosis(
            "checksum",
            computed,
            "its checksum digits were damaged; the record itself is intact (its bytes chain into "
            "the next record)",
            body + sep + b"%08x" % computed,
        )
    if stored is None:
        return Diagnosis("unproven", None, "")
    bit = _flipped_bit(line, computed, stored, seq=seq, stream=stream, id_key=id_key, proves=proves)
    if bit is not None:
        return bit
    if not proves(stored):
        return Diagnosis("unproven", None, "")
    ours = _belongs(event, seq, stream) and (
        event is not None and event.event_id == deterministic_event_id(id_key, seq)
    )
    if not (ours or _witness_is_ours(witness, id_key, seq)):
        # Neither it nor its witness carries this log's ids: both may have been spliced in from
        # another log (the witness chaining from it), so nothing proves it damaged here.
        return Diagnosis("unproven", None, "")
    return Diagnosis(
        "body",
        stored,
        "its bytes were damaged in more than one bit (or edited): they no longer match its "
        "checksum, which the next record proves is the one its writer wrote",
    )


def _proves(witness: Witness, stream: str, value: int, expect: int) -> bool:
    """Whether the witness chains from ``value``: the next record decodes with it as its
    predecessor's checksum (and is seq ``expect`` of ``stream``), or the high-water mark is it."""
    if witness.next_line is not None:
        try:
            event, _ = decode_record(witness.next_line, value)
        except RecordError:
            return False
        return event.seq == expect and event.stream == stream
    return witness.mark_checksum is not None and witness.mark_checksum == value


def _witness_is_ours(witness: Witness, id_key: str, seq: int) -> bool:
    """The witness was written by this log's writer: the high-water mark, or a next record
    with this log's own default id (a record spliced in from another log, with its
    successor, has another log's ids)."""
    if witness.next_line is None:
        return witness.mark_checksum is not None
    following = _event_of(witness.next_line.rpartition(RECORD_SEPARATOR)[0])
    return following is not None and following.event_id == deterministic_event_id(id_key, seq + 1)


def _flipped_bit(
    line: bytes,
    computed: int,
    stored: int,
    *,
    seq: int,
    stream: str,
    id_key: str,
    proves: Callable[[int], bool],
) -> Diagnosis | None:
    """The "bit" diagnosis, if one flipped bit turns ``line`` back into this log's own record."""
    body, sep, crc = line.rpartition(RECORD_SEPARATOR)
    flipped = single_bit_error(computed ^ stored, len(body))
    if flipped is None:
        return None
    index, bit = flipped
    fixed = bytearray(body)
    fixed[index] ^= 1 << bit
    original = _event_of(bytes(fixed))
    # One flipped bit that turns it back into this log's own record at this seq is proof
    # enough: of the 2^32 syndromes, only 8 per byte name a single bit (for a 400-byte
    # record, random damage matches one by chance ~7 times in 10^7, counted, not measured),
    # and the result must also parse as that record; the next record's chain, when there is
    # one, proves it again.
    if _belongs(original, seq, stream) and (
        proves(stored)
        or (original is not None and original.event_id == deterministic_event_id(id_key, seq))
    ):
        return Diagnosis(
            "bit",
            stored,
            f"one bit of it was flipped (byte {index} of the record, bit {bit}): the original "
            "is recovered exactly, proven by its own checksum",
            bytes(fixed) + sep + crc,
        )
    return None


def chain_before(body: bytes, checksum: int) -> int | None:
    """The chain value ``prev`` with ``zlib.crc32(body, prev) == checksum``: CRC-32 is affine
    in its starting value, so a 32 × 32 system over GF(2) gives it (None if singular)."""
    base = zlib.crc32(body, 0)
    columns = [zlib.crc32(body, 1 << k) ^ base for k in range(32)]
    # Gaussian elimination on rows (bit i of every column) | bit i of the target.
    target = checksum ^ base
    rows = []
    for i in range(32):
        row = sum(((columns[k] >> i) & 1) << k for k in range(32))
        rows.append((row, (target >> i) & 1))
    solution = 0
    pivots: list[tuple[int, int, int]] = []
    for k in range(32):
        pivot = next((r for r in range(len(rows)) if (rows[r][0] >> k) & 1), None)
        if pivot is None:
            return None
        prow, pval = rows.pop(pivot)
        rows = [(r ^ prow, v ^ pval) if (r >> k) & 1 else (r, v) for r, v in rows]
        pivots.append((k, prow, pval))
    for k, prow, pval in reversed(pivots):
        others = prow & ~(1 << k)
        bit = pval ^ (bin(others & solution).count("1") & 1)
        solution |= bit << k
    return solution if zlib.crc32(body, solution) == checksum else None


def single_bit_error(syndrome: int, length: int) -> tuple[int, int] | None:
    """(byte index, bit) of the one flipped bit of a ``length``-byte message whose CRC-32 is off
    by ``syndrome`` (computed XOR stored), or None if no single bit explains it.

    CRC-32 is linear: flipping one bit changes the CRC by a value that depends only on the bit's
    distance from the end, which this walks back from the last byte (8 table steps per byte).
    """
    if syndrome == 0:
        return None
    states = [_TABLE[1 << bit] for bit in range(8)]
    for distance in range(length):
        for bit, state in enumerate(states):
            if state == syndrome:
                return length - 1 - distance, bit
        states = [(s >> 8) ^ _TABLE[s & 0xFF] for s in states]
    return None


def _event_of(body: bytes) -> Event | None:
    try:
        doc = json.loads(body)
        return Event._adopt(doc) if isinstance(doc, dict) else None
    except (ValueError, InvalidEventError):
        return None


def _belongs(event: Event | None, seq: int, stream: str) -> bool:
    return event is not None and event.seq == seq and event.stream == stream
