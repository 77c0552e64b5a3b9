"""A fold straight from a log's records (issue 46): ``fold(read_log(...), projection)`` without
an :class:`~.envelope.Event` per record, for a projection that names what it reads
(:class:`RecordFold`).

The scan (:mod:`.scan`) checks one line at a time and builds an event whose payload a fold then
decodes; here a block of lines is checked together and each line decoded once, envelope and
payload at the same time, straight into the record the fold reads (a msgspec union of one
envelope struct per event type, tagged by ``type``). The checks are the scan's, run over the
block: the chained checksum of every line, the envelope's types and constraints (in C, as the
scan's decoder has them), the stream, the known type at its latest version, seq continuity, time
order, the ids' spelling (one regex over the block), a payload that is an object, and the
durable mark. A block where any of them fails, or that holds a type the projection must see as
an event (``None`` in its handlers), or an old version (to be upcast), is read again by the scan
itself and folded event by event, so what is refused, how the refusal is worded and what an
upcaster makes of an old record are the scan's; so are a torn tail and the durable mark at the
end (the rest of the log after the last complete line is always the scan's).
"""

from __future__ import annotations

import zlib
from collections.abc import Callable, Mapping
from itertools import repeat
from operator import attrgetter, length_hint
from pathlib import Path
from struct import unpack
from typing import Annotated, Any, Final, Literal, Protocol, Union, runtime_checkable

import msgspec

from .envelope import Event, canonical_ids, decode_event
from .log_files import Durable, LogMeta, TornTail
from .scan import QUARANTINED_TYPE, _Cursor, _Scan
from .store import Store

#: What a handler is given: the record's place and its payload, decoded as its type's record.
RecordHandler = Callable[[Any], None]


@runtime_checkable
class RecordFold(Protocol):
    """A projection that can be folded from records (:func:`fold_records`)."""

    @property
    def last_seq(self) -> int: ...

    def apply(self, event: Event) -> None: ...

    def record_handlers(self) -> Mapping[str, RecordHandler | None] | None:
        """What this fold does with each event type, as it stands now (asked again before each
        block): a handler, given the record's ``seq``, ``time_ns``, ``task_id`` and ``payload``
        (the type's latest record); ``None``: the type must reach :meth:`apply` as an event; a
        type not named is not read (its record is still checked as the scan checks it). None:
        fold the next block event by event. The same mapping, while the handlers are the same
        (its decoder is then made once)."""
        ...

    def folded_to(self, seq: int, time_ns: int) -> None:
        """The records up to ``seq`` (its ``time_ns``) were handed to the handlers: advance
        ``last_seq`` as :meth:`apply` would have."""
        ...


class _Object(msgspec.Struct, frozen=True, gc=False):
    """A payload a fold does not read: any JSON object (the scan checks no more of it)."""


_Name = Annotated[str, msgspec.Meta(min_length=1)]
_Count = Annotated[int, msgspec.Meta(ge=0)]
_Positive = Annotated[int, msgspec.Meta(ge=1)]
_IdLength = Annotated[str, msgspec.Meta(min_length=36, max_length=36)]

#: A block: about 170 of the agent's records. Small enough that the block's records stay in the
#: CPU's caches (a block of 1 MB was slower than line by line), large enough that its checks run
#: as a few calls in C.
_BLOCK: Final = 1 << 16

_seqs: Final = attrgetter("seq")
_times: Final = attrgetter("time_ns")
_ids: Final = attrgetter("event_id")


def _decoder(
    stream: str, records: Mapping[str, tuple[int, type[msgspec.Struct] | None]]
) -> tuple[Callable[[bytes], Any], dict[type, str]]:
    """One envelope struct per event type (tagged by ``type``), the scan's envelope constraints,
    the stream and the type's latest version as literals, and the payload as the type's record
    (or any object); and each struct's event type."""
    structs: dict[type, str] = {}
    for event_type, (version, record) in records.items():
        struct = msgspec.defstruct(
            f"_Fold_{event_type}",
            [
                ("event_id", _IdLength),
                ("stream", Literal[stream]),
                ("seq", _Positive),
                ("time_ns", _Count),
                ("recorded_at_ns", _Count),
                ("version", Literal[version]),
                ("task_id", _Name | None),
                ("payload", _Object if record is None else record),
            ],
            tag_field="type",
            tag=event_type,
            kw_only=True,
            frozen=True,
            forbid_unknown_fields=True,
            gc=False,
        )
        structs[struct] = event_type
    union: Any = Union[tuple(structs)]  # noqa: UP007  (a union of types made at run time)
    return msgspec.json.Decoder(union).decode, structs


#: The decoders made, by stream, store and the handlers' types (a few per process, each a
#: union of some twenty structs: made in about 3 ms, so a bound, not an LRU).
_DECODERS: dict[tuple[str, int, tuple[tuple[str, bool], ...]], Any] = {}
_MAX_DECODERS: Final = 32


def _block_decoder(
    store: Store, stream: str, handlers: Mapping[str, RecordHandler | None]
) -> tuple[Callable[[bytes], Any], dict[type, RecordHandler]]:
    """The decoder for a projection's handlers (cached), and each struct's handler."""
    latest = store.upcaster.latest_versions
    records = store.catalogue.records
    known = store.registry.known
    key = (stream, id(store), tuple(sorted((t, h is None) for t, h in handlers.items())))
    cached = _DECODERS.get(key)
    if cached is None:
        wanted: dict[str, tuple[int, type[msgspec.Struct] | None]] = {}
        for event_type, version in latest.items():
            if event_type == QUARANTINED_TYPE or (event_type, version) not in known:
                continue  # the scan's: it reads the chain a quarantined record gives
            if event_type in handlers:
                if handlers[event_type] is None:
                    continue  # read as an event: the block is the scan's
                record = records.get((event_type, version))
                if record is None:
                    continue
                wanted[event_type] = (version, record)
            else:
                wanted[event_type] = (version, None)
        if len(_DECODERS) >= _MAX_DECODERS:
            _DECODERS.clear()  # a process that folds the logs of many streams: keep few
        cached = _DECODERS[key] = (_decoder(stream, wanted), store)  # keep the store alive
    (decode, structs), _ = cached
    by_struct = {s: handlers[t] for s, t in structs.items() if handlers.get(t) is not None}
    return decode, by_struct  # type: ignore[return-value]


def fold_records(
    path: Path,
    meta: LogMeta,
    durable: Durable | None,
    store: Store,
    projection: RecordFold,
    until_seq: int | None,
    apply_event: Callable[[Event], None],
) -> TornTail | None:
    """Fold the log at ``path`` into ``projection`` from its records, block by block; a block
    that is not all good records of the types the projection folds from records is read by the
    scan and each of its events handed to ``apply_event`` (``fold``'s checked apply, upcast
    first). Stops once ``until_seq`` is folded, as ``fold`` does. Returns the log's torn tail,
    if it was read to its end and has one (the caller reports it, as ``read_log`` does)."""
    tail: TornTail | None = None
    at = _Cursor(checksum=meta.genesis)
    chained = meta.chained
    stream = meta.stream
    mark_seq = durable.seq if durable is not None else -1
    upcast = store.upcaster.upcast
    latest = store.upcaster.latest_versions
    crc32 = zlib.crc32

    def by_events(count: int | None) -> bool:
        """The next ``count`` records (None: the rest of the log) through the scan; True once
        ``until_seq`` is folded."""
        nonlocal tail
        scan = _Scan(path, meta, registry=store.registry, durable=durable, start=at)
        events = iter(scan)
        done = False
        try:
            for event in events:
                if event.version < latest.get(event.type, 0):
                    event = upcast(event)
                if event.seq > projection.last_seq:
                    apply_event(event)
                if until_seq is not None and event.seq >= until_seq:
                    done = True
                    break
                if count is not None:
                    count -= 1
                    if count == 0:
                        break
        finally:
            close = getattr(events, "close", None)
            if close is not None:
                close()  # the scan's cursor written back
            s = scan.at
            at.move_to(s.offset, s.line, s.seq, s.checksum, s.time_ns)
            tail = scan.torn_tail
        return done

    try:
        f = path.open("rb")
    except FileNotFoundError:
        by_events(None)
        return tail
    misses = skip = 0
    made_for: Mapping[str, RecordHandler | None] | None = None
    decode: Callable[[bytes], Any] = _no_decoder
    by_struct: dict[type, RecordHandler] = {}
    with f:
        rest = b""
        while True:
            chunk = f.read(_BLOCK)
            if not chunk:
                break
            lines = chunk.split(b"\n")
            before = len(rest)
            if before:
                lines[0] = rest + lines[0]  # the line the last block cut (not the block copied)
            rest = lines.pop()  # what follows the last newline
            if not lines:
                continue  # no newline yet: all of it is ``rest``
            cut = before + len(chunk) - len(rest)  # the block's complete lines, in bytes
            handlers = projection.record_handlers()
            folded = False
            if skip:
                skip -= 1  # blocks after some the scan had to read: the scan's too
            elif handlers is not None:
                if handlers is not made_for:  # the same handlers: the same decoder
                    decode, by_struct = _block_decoder(store, stream, handlers)
                    made_for = handlers
                folded = _fold_block(lines, cut, at, chained, mark_seq, durable, decode,
                                     by_struct, projection, until_seq, crc32, stream, store,
                                     apply_event, handlers)  # fmt: skip
                # A log of old versions (a perfect detector's detections v2) fails block after
                # block: after k failures in a row the next 2**k - 1 blocks go to the scan
                # directly, so such a log costs what the scan costs, and a log upgraded half way
                # is read from records again soon after its first new block.
                misses = 0 if folded else misses + 1
                skip = (1 << min(misses, 6)) - 1
            if not folded and by_events(len(lines)):
                return None
            if until_seq is not None and at.seq >= until_seq:
                return None
    by_events(None)  # a torn tail, the durable mark at the end: the scan's
    return tail


def _as_events(
    bodies: list[bytes],
    decode: Callable[[bytes], Any],
    stream: str,
    known: frozenset[tuple[str, int]],
    latest: Mapping[str, int],
) -> list[Any] | None:
    """Each of ``bodies`` as a record, or, if the union does not take it, as the scan's event
    (:data:`~.envelope.decode_event`: its envelope and id checked, its payload an object) of
    this stream and a known type at its latest version; None if one is neither (the block is
    the scan's)."""
    out: list[Any] = []
    keep = out.append
    for body in bodies:
        try:
            keep(decode(body))
            continue
        except msgspec.MsgspecError:
            pass
        try:
            event = decode_event(body)
        except msgspec.MsgspecError:
            return None
        if (
            event.stream != stream
            or (event.type, event.version) not in known
            or event.type == QUARANTINED_TYPE
            or event.version < latest.get(event.type, 0)
        ):
            # An old version is upcast from its dict: no cheaper here than in the scan, and a
            # block of them (the perfect detector's detections v2) was slower read this way.
            return None
        keep(event)
    return out


def _checksums(
    lines: list[bytes],
    bodies: list[bytes],
    chain: int | None,
    crc32: Callable[[bytes, int], int],
) -> list[int] | None:
    """Each line's checksum, chained from ``chain`` (None: not chained), if every line ends in
    a tab and 8 lowercase hex digits, those of its checksum (None otherwise).

    The scan's test, in a few calls in C: the lines' last 9 bytes joined are a tab and 8 digits
    per line (each slice is at most 9 bytes long, so 9 per line in all means 9 in each), read
    as numbers and written back to the same text (so no upper case, no blank); then each line's
    checksum is taken from the one the line before it claims. Every claim matching the checksum
    taken from the claim before it is every claim matching the chain from ``chain`` (by
    induction from the first line), which is what the scan checks line by line."""
    n = len(lines)
    tails = b"".join([line[-9:] for line in lines])
    if len(tails) != 9 * n or tails[::9] != b"\t" * n:
        return None
    digits = tails.replace(b"\t", b"").decode("latin-1")
    if len(digits) != 8 * n:
        return None
    try:
        raw = bytes.fromhex(digits)
    except ValueError:
        return None
    if raw.hex() != digits:
        return None
    claimed: tuple[int, ...] = unpack(f">{n}I", raw)  # the format is cached by struct
    if chain is None:
        taken = tuple(map(crc32, bodies, repeat(0, n)))
    else:
        taken = tuple(map(crc32, bodies, (chain, *claimed[:-1])))
    if taken != claimed:
        return None
    return list(claimed)


def _no_decoder(body: bytes) -> Any:
    raise AssertionError("no handlers yet")


def _fold_block(
    lines: list[bytes],
    size: int,
    at: _Cursor,
    chained: bool,
    mark_seq: int,
    durable: Durable | None,
    decode: Callable[[bytes], Any],
    by_struct: dict[type, RecordHandler],
    projection: RecordFold,
    until_seq: int | None,
    crc32: Callable[[bytes, int], int],
    stream: str,
    store: Store,
    apply_event: Callable[[Event], None],
    handlers: Mapping[str, RecordHandler | None],
) -> bool:
    """Check ``lines`` (a block of complete records, ``size`` bytes with their newlines) as the
    scan would and fold them with the handlers of ``by_struct`` (``decode``'s structs); False,
    having changed nothing, if any check fails or a record must be read as an event (the caller
    reads the block with the scan)."""
    known = store.registry.known
    latest = store.upcaster.latest_versions
    upcast = store.upcaster.upcast
    # A record is its JSON, a tab, its checksum in 8 hex digits: the last tab (where the scan
    # splits the line) is the 9th byte from the end iff the line ends as ``_checksums`` says.
    bodies = [line[:-9] for line in lines]
    values = _checksums(lines, bodies, at.checksum if chained else None, crc32)
    if values is None:
        return False
    every_one_a_record = True
    try:
        records: list[Any] = [decode(body) for body in bodies]
    except msgspec.MsgspecError:
        every_one_a_record = False
        # A record the union does not take (an old version, a type folded as an event, or a
        # bad one): those read as the scan reads them, into events, the rest as records.
        events = _as_events(bodies, decode, stream, known, latest)
        if events is None:
            return False
        records = events
    first = at.seq + 1
    seqs = list(map(_seqs, records))
    if seqs != list(range(first, first + len(seqs))):
        return False
    times = list(map(_times, records))
    if times[0] < at.time_ns or times != sorted(times):
        return False
    if not canonical_ids(list(map(_ids, records))):
        return False
    last = seqs[-1]
    if first <= mark_seq <= last:
        assert durable is not None
        k = mark_seq - first
        end = at.offset + sum(map(len, lines[: k + 1])) + k + 1
        if end != durable.offset or values[k] != durable.checksum:
            return False
    # Every record is good: fold those after the projection's place, up to ``until_seq``.
    begin = max(0, projection.last_seq + 1 - first)
    stop = len(records) if until_seq is None else max(0, min(len(records), until_seq - first + 1))
    if every_one_a_record:
        _handle_records(records[begin:stop], begin, by_struct, projection, seqs, times)
    else:
        handled = begin
        get = by_struct.get
        try:
            for record in records[begin:stop]:
                handler = get(type(record))
                if handler is not None:
                    handler(record)
                elif isinstance(record, Event):
                    # Folded as read_log hands it out (upcast first), once the records before
                    # it are folded to their place.
                    if handled > begin:
                        projection.folded_to(seqs[handled - 1], times[handled - 1])
                    apply_event(record if record.version >= latest.get(record.type, 0)
                                else upcast(record))  # fmt: skip
                    if projection.record_handlers() is not handlers:
                        # The event changed what the fold reads (the agent's first run_started
                        # builds its model): the rest of the block is folded as events.
                        handled += 1
                        for body in bodies[handled:stop]:
                            event = decode_event(body)  # checked above: it reads
                            apply_event(event if event.version >= latest.get(event.type, 0)
                                        else upcast(event))  # fmt: skip
                            handled += 1
                        break
                handled += 1
        finally:
            if handled > begin:
                projection.folded_to(seqs[handled - 1], times[handled - 1])
    if stop < len(records):
        # Stopped at ``until_seq``: the cursor stays on the last record folded.
        offset = at.offset + sum(map(len, lines[:stop])) + stop
        at.move_to(offset, at.line + stop, seqs[stop - 1], values[stop - 1], times[stop - 1])
        return True
    at.move_to(at.offset + size, at.line + len(lines), last, values[-1], times[-1])
    return True


def _handle_records(
    records: list[Any],
    begin: int,
    by_struct: dict[type, RecordHandler],
    projection: RecordFold,
    seqs: list[int],
    times: list[int],
) -> None:
    """``records`` (the block's from index ``begin``, none an event) each to its type's handler,
    the handlers found in C; then the projection advanced to the last, or, if a handler raises,
    to the one before the record it raised on (as the loop over a mixed block leaves it)."""
    left = iter(records)
    try:
        for handler, record in zip(map(by_struct.get, map(type, records)), left, strict=True):
            if handler is not None:
                handler(record)
    except BaseException:
        # zip took the record that raised from ``left`` (after its handler from the map).
        handled = begin + len(records) - length_hint(left) - 1
        if handled > begin:
            projection.folded_to(seqs[handled - 1], times[handled - 1])
        raise
    if records:
        end = begin + len(records)
        projection.folded_to(seqs[end - 1], times[end - 1])
