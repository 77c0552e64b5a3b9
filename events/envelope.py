"""The immutable event record (the envelope) and its JSON form."""

from __future__ import annotations

import hashlib
import math
import numbers
import re
import uuid
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Final, NoReturn, TypeGuard

from .errors import InvalidEventError

# Fixed forever: changing it would change the id of every event already written without an
# explicit id. (It is uuid5(NAMESPACE_URL, "urn:objsearch:events").)
EVENT_ID_NAMESPACE: Final = uuid.UUID("d5d2c2b6-eb95-54bd-bb91-8142ed50e621")

ENVELOPE_FIELDS: Final = (
    "event_id",
    "stream",
    "seq",
    "time_ns",
    "recorded_at_ns",
    "type",
    "version",
    "task_id",
    "payload",
)


def deterministic_event_id(run: str, seq: int) -> str:
    """The id of the ``seq``-th event of ``run``: ``uuid5(EVENT_ID_NAMESPACE, f"{run}/{seq}")``.

    A format-2 log passes its run id (unique per log, recorded in ``meta.json``), so two logs
    never share an id for different facts; a seeded simulation that derives its run id from its
    inputs still writes identical logs (up to the wall clock). Format-1 logs passed the stream.
    """
    # uuid.uuid5 spelled out (SHA-1 of namespace + name, version and variant bits): the same
    # string, without building two UUID objects per id — bag ingest numbers ~10^5 events a bag.
    digest = bytearray(hashlib.sha1(_NAMESPACE_BYTES + f"{run}/{seq}".encode()).digest()[:16])
    digest[6] = (digest[6] & 0x0F) | 0x50
    digest[8] = (digest[8] & 0x3F) | 0x80
    h = digest.hex()
    return f"{h[:8]}-{h[8:12]}-{h[12:16]}-{h[16:20]}-{h[20:]}"


_NAMESPACE_BYTES: Final = EVENT_ID_NAMESPACE.bytes


@dataclass(frozen=True, slots=True, kw_only=True)
class Event:
    """One immutable fact in a stream.

    ``payload`` is deep-copied on construction (tuples become lists, numpy scalars plain numbers,
    so an event equals itself after a JSON round trip) and exposed through a read-only mapping, so
    neither the caller's dict nor ``event.payload[...] = ...`` can change a recorded fact. Nested
    containers are plain JSON lists/dicts: treat them as read-only too.
    """

    event_id: str
    stream: str
    seq: int
    time_ns: int
    recorded_at_ns: int
    type: str
    version: int
    task_id: str | None
    payload: Mapping[str, Any]

    def __post_init__(self) -> None:
        check_envelope(
            event_id=self.event_id,
            stream=self.stream,
            seq=self.seq,
            time_ns=self.time_ns,
            recorded_at_ns=self.recorded_at_ns,
            type=self.type,
            version=self.version,
            task_id=self.task_id,
        )
        if not isinstance(self.payload, Mapping):
            raise InvalidEventError(
                f"invalid {self.type} v{self.version} event: payload: "
                f"{type(self.payload).__name__} is not a JSON object (mapping)",
                event_type=self.type,
                version=self.version,
                path="payload",
                reason="not a mapping",
            )
        copied = _json_copy(self.payload, "payload", self.type, self.version)
        object.__setattr__(self, "payload", MappingProxyType(copied))

    # The generated hash would fail on the mapping proxy; (stream, seq, id) identifies an event
    # and is equal for equal events, which is all hashing needs.
    def __hash__(self) -> int:
        return hash((self.stream, self.seq, self.event_id))

    def to_json_dict(self) -> dict[str, Any]:
        """A fresh, mutable, JSON-serialisable dict (the caller may change it freely)."""
        d = self.envelope_dict()
        d["payload"] = _json_copy(self.payload, "payload", self.type, self.version)
        return d

    def envelope_dict(self) -> dict[str, Any]:
        """Like :meth:`to_json_dict` but the payload's nested values are shared, not copied.

        For serialising; do not mutate the result's payload.
        """
        return {
            "event_id": self.event_id,
            "stream": self.stream,
            "seq": self.seq,
            "time_ns": self.time_ns,
            "recorded_at_ns": self.recorded_at_ns,
            "type": self.type,
            "version": self.version,
            "task_id": self.task_id,
            "payload": dict(self.payload),
        }

    @classmethod
    def from_json_dict(cls, d: Mapping[str, Any]) -> Event:
        """The inverse of :meth:`to_json_dict`: all envelope fields required, no others."""
        _check_field_names(d)
        return cls(**{name: d[name] for name in ENVELOPE_FIELDS})

    @classmethod
    def _adopt(cls, d: dict[str, Any]) -> Event:
        """Build from a dict the caller owns outright (fresh from ``json.loads``), without copying.

        The reader's hot path, for records whose checksum already proved they are what a writer
        wrote: the fields' presence and JSON types are checked, but neither the payload's deep
        copy nor the UUID parse, which together would double the cost of reading a log.
        """
        if d.keys() != _FIELD_SET:
            _check_field_names(d)
        payload = d["payload"]
        if not _plausible_envelope(d):
            check_envelope(**{name: d[name] for name in ENVELOPE_FIELDS if name != "payload"})
        if type(payload) is not dict:
            raise InvalidEventError(
                f"invalid event envelope: payload: {type(payload).__name__} is not a JSON object",
                path="payload",
                reason="not an object",
            )
        event = object.__new__(cls)
        for name in _SCALAR_FIELDS:
            object.__setattr__(event, name, d[name])
        object.__setattr__(event, "payload", MappingProxyType(payload))
        return event


_FIELD_SET: Final = frozenset(ENVELOPE_FIELDS)
_SCALAR_FIELDS: Final = tuple(name for name in ENVELOPE_FIELDS if name != "payload")


def _plausible_envelope(d: dict[str, Any]) -> bool:
    """check_envelope's rules minus the UUID parse, for values straight from ``json.loads``."""
    task_id = d["task_id"]
    return (
        type(d["event_id"]) is str
        and _CANONICAL_UUID.fullmatch(d["event_id"]) is not None
        and type(d["stream"]) is str
        and d["stream"] != ""
        and type(d["seq"]) is int
        and d["seq"] >= 1
        and type(d["time_ns"]) is int
        and d["time_ns"] >= 0
        and type(d["recorded_at_ns"]) is int
        and d["recorded_at_ns"] >= 0
        and type(d["type"]) is str
        and d["type"] != ""
        and type(d["version"]) is int
        and d["version"] >= 1
        and (task_id is None or (type(task_id) is str and task_id != ""))
    )


def check_envelope(
    *,
    event_id: object,
    stream: object,
    seq: object,
    time_ns: object,
    recorded_at_ns: object,
    type: object,
    version: object,
    task_id: object,
) -> None:
    """Raise :class:`InvalidEventError` naming the first envelope field that is wrong."""
    problem: tuple[str, object, str] | None = None
    if not (isinstance(event_id, str) and _is_canonical_uuid(event_id)):
        problem = ("event_id", event_id, "is not a canonical UUID string")
    elif not (isinstance(stream, str) and stream):
        problem = ("stream", stream, "is not a non-empty string")
    elif not (_is_int(seq) and seq >= 1):
        problem = ("seq", seq, "is not an integer >= 1")
    elif not (_is_int(time_ns) and time_ns >= 0):
        problem = ("time_ns", time_ns, "is not an integer >= 0")
    elif not (_is_int(recorded_at_ns) and recorded_at_ns >= 0):
        problem = ("recorded_at_ns", recorded_at_ns, "is not an integer >= 0")
    elif not (isinstance(type, str) and type):
        problem = ("type", type, "is not a non-empty string")
    elif not (_is_int(version) and version >= 1):
        problem = ("version", version, "is not an integer >= 1")
    elif not (task_id is None or (isinstance(task_id, str) and task_id)):
        problem = ("task_id", task_id, "is neither null nor a non-empty string")
    if problem is not None:
        field, value, reason = problem
        raise InvalidEventError(
            f"invalid event envelope: {field}: {value!r} {reason}",
            event_type=type if isinstance(type, str) else None,
            version=version if _is_int(version) else None,
            path=field,
            reason=f"{value!r} {reason}",
        )


def _check_field_names(d: Mapping[str, Any]) -> None:
    missing = [name for name in ENVELOPE_FIELDS if name not in d]
    unknown = sorted(str(name) for name in d if name not in ENVELOPE_FIELDS)
    if missing or unknown:
        parts = []
        if missing:
            parts.append("missing field(s) " + ", ".join(map(repr, missing)))
        if unknown:
            parts.append("unknown field(s) " + ", ".join(map(repr, unknown)))
        raise InvalidEventError(
            "invalid event envelope: " + "; ".join(parts), reason="; ".join(parts)
        )


def _is_int(value: object) -> TypeGuard[int]:
    # bool is an int subclass, but True is not a sequence number.
    return isinstance(value, int) and not isinstance(value, bool)


# uuid.UUID also accepts braces, "urn:uuid:" and upper case; only one spelling per id keeps ids
# comparable as strings. This is exactly the set of strings with str(uuid.UUID(s)) == s.
_CANONICAL_UUID: Final = re.compile(
    r"[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}", re.ASCII
)


def _is_canonical_uuid(value: str) -> bool:
    return _CANONICAL_UUID.fullmatch(value) is not None


def _json_copy(value: Any, path: str, event_type: str, version: int) -> Any:
    """A deep copy restricted to JSON types: what ``json.dumps`` then ``json.loads`` would give.

    Normalising here (tuple → list, numpy scalar → int/float) keeps an appended event equal to
    the same event read back; refusing NaN/inf and non-JSON objects here keeps them off disk.
    """
    if value is None or type(value) in (str, int, bool):
        return value
    if type(value) is float:
        if not math.isfinite(value):
            _not_json(value, path, event_type, version, "is not a finite number")
        return value
    if isinstance(value, Mapping):
        out: dict[str, Any] = {}
        for key, item in value.items():
            if not isinstance(key, str):
                _not_json(key, path, event_type, version, "is not a string key")
            out[str.__str__(key)] = _json_copy(item, f"{path}.{key}", event_type, version)
        return out
    if isinstance(value, list | tuple):
        return [
            _json_copy(item, f"{path}[{i}]", event_type, version) for i, item in enumerate(value)
        ]
    # Subclasses (StrEnum, IntEnum, numpy scalars) become the plain value JSON would store.
    if isinstance(value, str):
        return str.__str__(value)
    if isinstance(value, bool):
        return bool(value)
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        return _json_copy(float(value), path, event_type, version)
    _not_json(value, path, event_type, version, "is not a JSON value (use list/dict/str/number)")


def _not_json(value: object, path: str, event_type: str, version: int, reason: str) -> NoReturn:
    described = f"{value!r} ({type(value).__name__}) {reason}"
    raise InvalidEventError(
        f"invalid {event_type} v{version} event: {path}: {described}",
        event_type=event_type,
        version=version,
        path=path,
        reason=described,
    )
