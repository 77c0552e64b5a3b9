"""One line of ``events.log``: ``<JSON envelope>\\t<crc32 as 8 lower-case hex digits>\\n``.

The JSON is compact with sorted keys so the same event always has the same bytes. ``json.dumps``
escapes every control character, so the JSON never holds a raw tab or newline: a line is split
at its last tab, and lines at ``\\n`` bytes (never at text line breaks: ``ensure_ascii=False``
leaves U+2028 raw, which ``str.splitlines`` would split).
"""

from __future__ import annotations

import json
import zlib
from typing import Final

from .envelope import Event
from .errors import InvalidEventError

RECORD_SEPARATOR: Final = b"\t"
RECORD_END: Final = b"\n"


class RecordError(Exception):
    """A line is not a valid record.

    ``intact`` says the checksum matched: the bytes are exactly what a writer wrote, so the damage
    cannot come from an interrupted write and is never treated as a torn tail.
    """

    def __init__(self, reason: str, *, intact: bool) -> None:
        super().__init__(reason)
        self.reason = reason
        self.intact = intact


def encode_record(event: Event) -> bytes:
    """The full line for ``event`` (newline included); ``InvalidEventError`` if unstorable."""
    try:
        text = json.dumps(
            event.envelope_dict(),
            sort_keys=True,
            separators=(",", ":"),
            ensure_ascii=False,
            allow_nan=False,
        )
        body = text.encode("utf-8")
    except ValueError as exc:  # NaN/inf, or a lone surrogate that UTF-8 cannot encode
        raise InvalidEventError(
            f"invalid {event.type} v{event.version} event: cannot be stored as UTF-8 JSON: {exc}",
            event_type=event.type,
            version=event.version,
            reason=str(exc),
        ) from exc
    return body + b"\t%08x\n" % zlib.crc32(body)


def checksum_ok(line: bytes) -> bool:
    """Whether a line (without its newline) carries a matching checksum, whatever its JSON."""
    body, sep, crc = line.rpartition(RECORD_SEPARATOR)
    return bool(sep) and crc == b"%08x" % zlib.crc32(body)


def decode_record(line: bytes) -> Event:
    """Parse one line (without its newline); raise :class:`RecordError` saying what is wrong."""
    body, sep, crc = line.rpartition(RECORD_SEPARATOR)
    if not sep:
        raise RecordError("no tab separating the JSON from its checksum", intact=False)
    computed = b"%08x" % zlib.crc32(body)
    if crc != computed:
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
        return Event._adopt(data)
    except InvalidEventError as exc:
        raise RecordError(f"checksum matches but {exc}", intact=True) from exc
