"""A typed record's payload as a log stores it, made in C: what :meth:`EventLog.append_record
<objsearch.events.log.EventLog.append_record>` writes without building the payload's dict.

A domain that defines its payloads as ``msgspec.Struct`` records (``Catalogue.records``) appends
them as they are. The record's JSON is made by msgspec with sorted keys, which is the text
``json.dumps(payload, sort_keys=True, separators=(",", ":"), ensure_ascii=False)`` of the
record's dict in every case but one: floats that Python spells with an exponent (below 1e-4 or
from 1e16 on: ``1e-05``, ``1e+16``) msgspec spells ``0.00001`` and ``1e16``. A text that may
hold one of those (:data:`_EXPONENT`, :data:`_TINY`; they also match look-alikes inside strings)
is not used, and the caller takes the dict path. The text is then decoded back into the record's
type, strictly, in C: the check an append of the dict gets from the record (``accepts``), so a
record built with a wrong value (msgspec does not check types when a Struct is made) is
refused, by the dict path, with its usual error.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from typing import Any, Final

import msgspec

_encode_sorted: Final = msgspec.json.Encoder(order="sorted").encode
_encode: Final = msgspec.json.Encoder().encode
_decode_dict: Final = msgspec.json.Decoder(dict[str, Any]).decode

#: What a float msgspec spells otherwise than ``json`` holds: an exponent (``1e16``, ``2.5e-7``:
#: an ``e`` then a digit or a minus) or a decimal below 1e-4 (``0.00001``). A match inside a string
#: (``"routine-0"``) only sends the record down the dict path. Two scans that start from a
#: literal, not one regex that tries every number: 2.3× faster on a detection's text.
_EXPONENT: Final = re.compile(rb"e[-0-9]")
_TINY: Final = b"0.0000"


class RecordCodec:
    """One record type of a catalogue: its event type and version, its strict JSON decoder, its
    payload's JSON (or None: take the dict path) and its payload as a dict."""

    __slots__ = ("decode", "type", "version")

    def __init__(self, event_type: str, version: int, record_type: type[msgspec.Struct]) -> None:
        self.type: Final = event_type
        self.version: Final = version
        #: The record from a payload's JSON, every constraint checked (the one decoder of this
        #: record: appends check with it, folds read with it).
        self.decode: Final[Callable[[bytes | msgspec.Raw], Any]] = msgspec.json.Decoder(
            record_type, strict=True
        ).decode

    def payload_json(self, record: msgspec.Struct) -> bytes | None:
        """The payload's JSON exactly as an append of :meth:`payload` stores it, if it is made
        here and the record fits its type; None sends the caller down the dict path."""
        try:
            text = _encode_sorted(record)
        except (msgspec.EncodeError, TypeError, ValueError, OverflowError):
            return None  # a lone surrogate, an object msgspec cannot encode: the dict path words it
        if _TINY in text or _EXPONENT.search(text) is not None:
            return None
        try:
            self.decode(text)
        except msgspec.ValidationError:
            return None  # NaN (encoded as null), a value of the wrong type: refused there
        return text

    @staticmethod
    def payload(record: msgspec.Struct) -> dict[str, Any]:
        """The payload dict of ``record`` (JSON types only: tuples become lists)."""
        payload: dict[str, Any] = _decode_dict(_encode(record))
        return payload


def record_codecs(
    records: Mapping[tuple[str, int], type[msgspec.Struct]],
) -> dict[type[msgspec.Struct], RecordCodec]:
    """Each record type of a catalogue and its codec."""
    return {
        record_type: RecordCodec(event_type, version, record_type)
        for (event_type, version), record_type in records.items()
    }
