"""One line of ``events.log``: ``<JSON envelope>\\t<checksum as 8 lower-case hex digits>\\n``.

The JSON is compact with sorted keys so the same event always has the same bytes. ``json.dumps``
escapes every control character, so the JSON never holds a raw tab or newline: a line is split
at its last tab, and lines at ``\\n`` bytes (never at text line breaks: ``ensure_ascii=False``
leaves U+2028 raw, which ``str.splitlines`` would split).

The checksum is CRC-32 of the JSON bytes started from ``prev``. In a format-2 log ``prev`` is the
previous record's checksum (the first record's is the log's genesis value, from its stream and run
id), so each checksum covers its predecessor: a hash chain, which makes a spliced, reordered or
foreign record fail even though its own bytes are intact. Format-1 logs use ``prev = 0`` for every
record (a plain CRC-32 of the line).
"""

from __future__ import annotations

import json
import zlib
from collections.abc import Callable
from typing import Final

import msgspec

from .envelope import Event, decode_event
from .errors import InvalidEventError

RECORD_SEPARATOR: Final = b"\t"
RECORD_END: Final = b"\n"


class RecordError(Exception):
    """A line is not a valid record.

    ``intact`` says the checksum matched: the bytes are exactly what a writer wrote, so the damage
    is in what was written, not in how it was stored.
    """

    def __init__(self, reason: str, *, intact: bool) -> None:
        super().__init__(reason)
        self.reason = reason
        self.intact = intact


def encode_body(event: Event) -> bytes:
    """The JSON bytes of ``event``; ``InvalidEventError`` if it cannot be stored."""
    try:
        text = json.dumps(
            event.envelope_dict(),
            sort_keys=True,
            separators=(",", ":"),
            ensure_ascii=False,
            allow_nan=False,
        )
        return text.encode("utf-8")
    except ValueError as exc:  # NaN/inf, or a lone surrogate that UTF-8 cannot encode
        raise _unstorable(event, exc) from exc


def _unstorable(event: Event, exc: ValueError) -> InvalidEventError:
    return InvalidEventError(
        f"invalid {event.type} v{event.version} event: cannot be stored as UTF-8 JSON: {exc}",
        event_type=event.type,
        version=event.version,
        reason=str(exc),
    )


#: The record's JSON with the payload's text put in: the keys in sorted order, the strings as
#: ``json.dumps(..., ensure_ascii=False)`` writes them (:func:`encode_body`'s bytes exactly).
_BODY: Final = (
    '{"event_id":"%s","payload":%s,"recorded_at_ns":%d,"seq":%d,"stream":%s,"task_id":%s,'
    '"time_ns":%d,"type":%s,"version":%d}'
)
_string: Final[Callable[[str], str]] = json.encoder.encode_basestring


def encode_new_record(event: Event, payload_json: str | bytes, prev: int = 0) -> bytes:
    """:func:`encode_record` of an event being appended whose payload's JSON text
    (:func:`~objsearch.events.envelope.json_payload`) is already made: the envelope is written
    around it, not dumped again. ``InvalidEventError`` if it cannot be stored as UTF-8."""
    return frame_new_record(event, payload_json, prev)[0]


def frame_new_record(event: Event, payload_json: str | bytes, prev: int = 0) -> tuple[bytes, int]:
    """:func:`encode_new_record`'s line and its checksum (the next record's ``prev`` in a
    chained log), which the writer keeps rather than read back from the line's hex digits."""
    return Framer(event.stream).frame(event, payload_json, prev)


#: :data:`_BODY` for a payload's JSON made as UTF-8 bytes (a typed record's, by msgspec): the
#: line is made as bytes, the payload's text never decoded into a str and encoded again.
_BODY_BYTES: Final = _BODY.encode()


def _utf8(text: str) -> bytes | None:
    """``text`` as UTF-8, or None if it cannot be (a lone surrogate: the str path words it)."""
    try:
        return text.encode("utf-8")
    except UnicodeEncodeError:
        return None


class Framer:
    """:func:`frame_new_record` for the records of one stream: the stream's name, each event
    type and the last task id are escaped once, not once per record (a writer's appends)."""

    __slots__ = ("_stream", "_stream_bytes", "_task", "_task_bytes", "_task_json", "_types")

    def __init__(self, stream: str) -> None:
        self._stream = _string(stream)
        self._stream_bytes = _utf8(self._stream)
        #: each event type's JSON string, as str and as UTF-8 (None: it has a lone surrogate)
        self._types: dict[str, tuple[str, bytes | None]] = {}
        self._task: str | None = None
        self._task_json = "null"
        self._task_bytes: bytes | None = b"null"

    def frame(self, event: Event, payload_json: str | bytes, prev: int) -> tuple[bytes, int]:
        """``event``'s line (``payload_json`` its payload's JSON text, or that text as UTF-8
        bytes) and its checksum."""
        task_id = event.task_id
        if task_id != self._task:
            self._task_json = "null" if task_id is None else _string(task_id)
            self._task_bytes = _utf8(self._task_json)
            self._task = task_id
        event_type = event.type
        type_json = self._types.get(event_type)
        if type_json is None:
            escaped = _string(event_type)
            type_json = self._types[event_type] = (escaped, _utf8(escaped))
        if type(payload_json) is bytes:
            stream, task, kind = self._stream_bytes, self._task_bytes, type_json[1]
            if stream is not None and task is not None and kind is not None:
                body = _BODY_BYTES % (
                    event.event_id.encode(),  # canonical (checked): ASCII, nothing to escape
                    payload_json,
                    event.recorded_at_ns,
                    event.seq,
                    stream,
                    task,
                    event.time_ns,
                    kind,
                    event.version,
                )
                checksum = zlib.crc32(body, prev)
                return body + b"\t%08x\n" % checksum, checksum
            payload_json = payload_json.decode()  # below, to word the lone surrogate's error
        text = _BODY % (
            event.event_id,  # canonical (checked): hex digits and dashes, nothing to escape
            payload_json,
            event.recorded_at_ns,
            event.seq,
            self._stream,
            self._task_json,
            event.time_ns,
            type_json[0],
            event.version,
        )
        try:
            body = text.encode("utf-8")
        except ValueError as exc:  # a lone surrogate
            raise _unstorable(event, exc) from exc
        checksum = zlib.crc32(body, prev)
        return body + b"\t%08x\n" % checksum, checksum


def encode_record(event: Event, prev: int = 0) -> bytes:
    """The full line for ``event`` (newline included), its checksum started from ``prev``."""
    body = encode_body(event)
    return body + b"\t%08x\n" % zlib.crc32(body, prev)


def record_checksum(line: bytes) -> int | None:
    """The checksum a line (without its newline) carries, or None if it has none."""
    _, sep, crc = line.rpartition(RECORD_SEPARATOR)
    if not sep or len(crc) != 8:
        return None
    try:
        return int(crc, 16)
    except ValueError:
        return None


def decode_record(line: bytes, prev: int = 0) -> tuple[Event, int]:
    """Parse one line (without its newline) whose checksum starts from ``prev``.

    Returns the event and its checksum (the next record's ``prev`` in a chained log); raises
    :class:`RecordError` saying what is wrong.
    """
    body, sep, crc = line.rpartition(RECORD_SEPARATOR)
    if not sep:
        raise RecordError("no tab separating the JSON from its checksum", intact=False)
    value = zlib.crc32(body, prev)
    computed = b"%08x" % value
    if crc == computed:
        try:
            # One decode, in C, envelope checked: the whole cost of a good record.
            return decode_event(body), value
        except msgspec.MsgspecError:
            pass  # read again below, to accept what json accepts and word what it refuses
    else:
        raise RecordError(
            f"checksum mismatch (stored {crc[:16].decode('ascii', 'replace')!r}, "
            f"computed {computed.decode('ascii')!r})",
            intact=False,
        )
    try:
        data = json.loads(body)
    except ValueError as exc:
        raise RecordError(f"checksum matches but the JSON is invalid: {exc}", intact=True) from exc
    if not isinstance(data, dict):
        raise RecordError("checksum matches but the JSON is not an object", intact=True)
    try:
        return Event._adopt(data), value
    except InvalidEventError as exc:
        raise RecordError(f"checksum matches but {exc}", intact=True) from exc
