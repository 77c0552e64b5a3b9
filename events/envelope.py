"""The immutable event record (the envelope) and its JSON form."""

from __future__ import annotations

import hashlib
import json
import math
import numbers
import re
import uuid
from collections.abc import Callable, Iterator, Mapping
from types import MappingProxyType
from typing import Annotated, Any, Final, NoReturn, TypeGuard

import msgspec

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
    # string, without building two UUID objects per id — bag ingest numbers ~10^5 events a bag,
    # a batched append one an event. The version nibble (hex digit 12) is 5; the variant's two
    # top bits (of hex digit 16) are 10.
    sha1 = _NAMESPACE_SHA1.copy()
    sha1.update(f"{run}/{seq}".encode())
    h = sha1.hexdigest()
    return f"{h[:8]}-{h[8:12]}-5{h[13:16]}-{_VARIANT_DIGIT[h[16]]}{h[17:20]}-{h[20:32]}"


def event_ids(run: str) -> Callable[[int], str]:
    """:func:`deterministic_event_id` of ``run`` as a function of the seq alone (a writer's
    default ids): the namespace and ``f"{run}/"`` are hashed once, and each id copies that
    state and hashes only the seq's digits. The same strings (``tests/events/test_envelope.py``
    holds them to ``uuid.uuid5`` over many seqs)."""
    prefix = _NAMESPACE_SHA1.copy()
    prefix.update(f"{run}/".encode())
    copy = prefix.copy
    variant = _VARIANT_DIGIT

    def event_id(seq: int) -> str:
        sha1 = copy()
        sha1.update(b"%d" % seq)
        h = sha1.hexdigest()
        return f"{h[:8]}-{h[8:12]}-5{h[13:16]}-{variant[h[16]]}{h[17:20]}-{h[20:32]}"

    return event_id


_NAMESPACE_SHA1: Final = hashlib.sha1(EVENT_ID_NAMESPACE.bytes)
_VARIANT_DIGIT: Final = {f"{n:x}": f"{(n & 0x3) | 0x8:x}" for n in range(16)}


# The envelope's rules as msgspec constraints: a record's envelope is checked in C as it is
# decoded (``check_envelope`` states the same rules for events built in Python). All but the
# event id's spelling: msgspec's ``pattern`` constraint cost 2.8 µs of a 3.5 µs envelope decode
# (measured), so the decoded events check it in ``__post_init__`` (:func:`_is_canonical_uuid`).
_Name = Annotated[str, msgspec.Meta(min_length=1)]
_Count = Annotated[int, msgspec.Meta(ge=0)]
_Positive = Annotated[int, msgspec.Meta(ge=1)]
#: The decoders' event id: its length checked in C (a canonical UUID string has 36 characters),
#: the rest of its spelling in ``__post_init__``.
_IdLength = Annotated[str, msgspec.Meta(min_length=36, max_length=36)]


class Event(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True, gc=False):
    """One immutable fact in a stream.

    ``payload`` is deep-copied on construction (tuples become lists, numpy scalars plain numbers,
    so an event equals itself after a JSON round trip) and exposed through a read-only mapping, so
    neither the caller's dict nor ``event.payload[...] = ...`` can change a recorded fact. Nested
    containers are plain JSON lists/dicts: treat them as read-only too.

    A ``msgspec.Struct`` rather than a dataclass: a log's record decodes straight into one, its
    envelope checked in C on the way (:data:`decode_event`), which is most of what reading costs.
    Equal events compare equal however they were made (built, or read back).
    """

    event_id: str
    stream: _Name
    seq: _Positive
    time_ns: _Count
    recorded_at_ns: _Count
    type: _Name
    version: _Positive
    task_id: _Name | None
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
        require_mapping(self.payload, self.type, self.version)
        copied = _json_copy(self.payload, "payload", self.type, self.version)
        msgspec.structs.force_setattr(self, "payload", MappingProxyType(copied))

    # (stream, seq, id) identifies an event and is equal for equal events, which is all hashing
    # needs (the payload, a mapping, has no hash).
    def __hash__(self) -> int:
        return hash((self.stream, self.seq, self.event_id))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Event):
            return NotImplemented
        return (
            self.seq == other.seq
            and self.event_id == other.event_id
            and self.stream == other.stream
            and self.time_ns == other.time_ns
            and self.recorded_at_ns == other.recorded_at_ns
            and self.type == other.type
            and self.version == other.version
            and self.task_id == other.task_id
            and self.payload == other.payload
        )

    def __ne__(self, other: object) -> bool:
        equal = self.__eq__(other)
        return equal if equal is NotImplemented else not equal

    def __repr__(self) -> str:
        fields = ", ".join(f"{name}={getattr(self, name)!r}" for name in ENVELOPE_FIELDS)
        return f"Event({fields})"

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
            "payload": _plain_dict(self.payload),
        }

    @classmethod
    def from_json_dict(cls, d: Mapping[str, Any]) -> Event:
        """The inverse of :meth:`to_json_dict`: all envelope fields required, no others."""
        _check_field_names(d)
        return cls(**{name: d[name] for name in ENVELOPE_FIELDS})

    @classmethod
    def _adopt(cls, d: dict[str, Any]) -> Event:
        """Build from a dict the caller owns outright (fresh from ``json.loads``), without copying.

        For records whose checksum already proved they are what a writer wrote: the fields'
        presence and JSON types are checked, but not the payload's deep copy.
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
        d = dict(d, payload=MappingProxyType(payload))
        return _Adopted(**d)

    @classmethod
    def _appended(
        cls,
        payload: Mapping[str, Any],
        *,
        event_id: str,
        stream: str,
        seq: int,
        time_ns: int,
        recorded_at_ns: int,
        type: str,
        version: int,
        task_id: str | None,
    ) -> Event:
        """The event an append stores: the envelope checked as ``Event(...)`` checks it, the
        payload the one the store checked and encoded (``Store.encode``: a read-only copy, or a
        record's JSON decoded only when read), wrapped, not copied again. The fields are named,
        not gathered into a dict and spread again: this runs once per append."""
        if not _plausible(event_id, stream, seq, time_ns, recorded_at_ns, type, version, task_id):
            check_envelope(  # words what is wrong (or lets an int subclass through, as Event does)
                event_id=event_id,
                stream=stream,
                seq=seq,
                time_ns=time_ns,
                recorded_at_ns=recorded_at_ns,
                type=type,
                version=version,
                task_id=task_id,
            )
        return _Adopted(
            event_id=event_id,
            stream=stream,
            seq=seq,
            time_ns=time_ns,
            recorded_at_ns=recorded_at_ns,
            type=type,
            version=version,
            task_id=task_id,
            payload=payload,
        )


class _Adopted(Event, frozen=True, kw_only=True, forbid_unknown_fields=True, gc=False):
    """An event whose builder checked its payload (``_adopt``, the appends): wrapped, not
    copied."""

    def __post_init__(self) -> None:
        kind = type(self.payload)
        if kind is not MappingProxyType and kind is not ReadPayload:  # a copy, another payload
            Event.__post_init__(self)


class ReadPayload(Mapping[str, Any]):
    """The payload of an event read from a log (or appended as a typed record: its JSON made in
    C), decoded only when first looked at; or of an event read from a lake run, its dict made
    from Arrow and its record converted with its slice of rows (:meth:`of`).

    A read that only verifies never builds it; a fold that wants the typed record decodes it
    from these JSON bytes straight into the record (:func:`payload_json`), one decode per event.
    Read-only, like every event's payload.
    """

    __slots__ = ("_dict", "record", "unread")

    def __init__(self, raw: bytes | msgspec.Raw) -> None:
        self._dict: dict[str, Any] | None = None
        #: The JSON text while the payload has not been decoded (then None): a reader that wants
        #: a typed record decodes it from here, once.
        self.unread: bytes | msgspec.Raw | None = raw
        #: The domain's typed record of this payload, once a fold has decoded it (None before):
        #: every other fold of the same event reads it instead of decoding the text again.
        #: Records are immutable, so sharing one is safe.
        self.record: Any = None

    @classmethod
    def of(cls, payload: dict[str, Any], record: Any = None) -> ReadPayload:
        """A payload whose dict is made already, owned by no one else (a lake row's, fresh from
        Arrow), wrapped, not copied; ``record``: its typed record if the reader converted it
        (:attr:`record`, as a fold keeps the one it decoded from a log's JSON)."""
        made = cls.__new__(cls)
        made._dict = payload
        made.unread = None
        made.record = record
        return made

    def _materialize(self) -> dict[str, Any]:
        d = self._dict
        if d is None:
            raw = self.unread
            assert raw is not None  # decoded once, then kept: one of the two is always set
            try:
                d = _decode_payload(raw)
            except msgspec.MsgspecError:  # what json reads and msgspec does not (1e400: inf)
                d = json.loads(bytes(raw))
            self._dict = d
            self.unread = None
        return d

    def __getitem__(self, key: str) -> Any:
        return self._materialize()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._materialize())

    def __len__(self) -> int:
        return len(self._materialize())

    def __contains__(self, key: object) -> bool:
        return key in self._materialize()

    def get(self, key: str, default: Any = None) -> Any:
        return self._materialize().get(key, default)

    def __eq__(self, other: object) -> bool:
        if isinstance(other, ReadPayload):
            return self._materialize() == other._materialize()
        if isinstance(other, Mapping):
            return self._materialize() == (other if type(other) is dict else dict(other))
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"ReadPayload({self._materialize()!r})"

    def copy(self) -> dict[str, Any]:
        """A shallow copy as a plain dict (nested values shared: do not change them)."""
        return dict(self._materialize())


def payload_json(payload: Mapping[str, Any]) -> bytes | msgspec.Raw | None:
    """The JSON text of a payload read from a log and not decoded yet (None otherwise): a reader
    that wants a typed record decodes it from here, once."""
    if type(payload) is ReadPayload:
        return payload.unread
    return None


class _Framed(Event, frozen=True, kw_only=True, forbid_unknown_fields=True, gc=False):
    """A record's envelope as the decoder checks it in C (types, constraints, the id's length),
    its payload left as JSON text (``msgspec.Raw``), never a mapping. Its ``__post_init__`` does
    nothing: the two rules msgspec does not check — the id's spelling and a payload that is an
    object — are the caller's, and the scans that only verify check them in batches
    (:func:`canonical_ids`). Checked per record in a ``__post_init__`` they made the decode about
    twice as slow (0.28 against 0.14 CPU-s for 100 k records, against a struct with no
    ``__post_init__`` at all, one process). Only those scans see these events."""

    event_id: _IdLength
    payload: msgspec.Raw  # type: ignore[assignment]

    def __post_init__(self) -> None:
        # Event's checks are for events built in Python; msgspec calls this for every record
        # decoded (it cannot be unset), so it is as short as a method can be.
        pass


class _Read(_Framed, frozen=True, kw_only=True, forbid_unknown_fields=True, gc=False):
    """An event decoded from a record: its envelope was checked by the decoder's constraints and
    its payload is kept as the record's JSON text until someone reads it (:class:`ReadPayload`)."""

    def __post_init__(self) -> None:
        # The rules msgspec does not check: the id's spelling (:func:`_is_canonical_uuid`
        # inlined; its length the decoder checked) and a payload that is an object; a
        # ``ValueError`` makes the decoder refuse the record. Inlined, not called: this runs once
        # per record, and a call is a measurable part of it. Then the payload wrapped.
        raw: object = self.payload
        if type(raw) is not msgspec.Raw:  # built in Python (msgspec.structs.replace)
            Event.__post_init__(self)
            return
        event_id = self.event_id
        if not (
            len(event_id) == 36
            and event_id[8] == event_id[13] == event_id[18] == event_id[23] == "-"
            and event_id.isascii()
            and event_id.encode().translate(None, _HEX_DIGITS) == b"----"
        ):
            raise ValueError("event_id is not a canonical UUID string")
        # The first byte through a copy: a memoryview costs more than copying a small payload.
        if bytes(raw)[:1] != b"{":
            raise ValueError("payload is not a JSON object")
        msgspec.structs.force_setattr(self, "payload", ReadPayload(raw))


_decode_payload: Final = msgspec.json.Decoder(dict[str, Any]).decode

#: The event of a record's JSON (the writer's compact, UTF-8 form), envelope checked; raises
#: ``msgspec.DecodeError`` / ``msgspec.ValidationError`` for anything else (a caller that must
#: say what is wrong reads it again with ``json.loads`` and :meth:`Event._adopt`). The decoder's
#: own method, not a function around it: a scan calls it once per record.
decode_event: Final[Callable[[bytes], Event]] = msgspec.json.Decoder(_Read).decode
#: Like :data:`decode_event`, but the payload is left as JSON text, not made a mapping, and
#: neither the id's spelling nor the payload's being an object is checked (:class:`_Framed`):
#: for a scan that verifies records, reads no payload and checks those itself.
frame_event: Final[Callable[[bytes], Event]] = msgspec.json.Decoder(_Framed).decode

_DASHES: Final = tuple(range(8, 24, 5))  # where a canonical id has its four dashes


def canonical_ids(ids: list[str]) -> bool:
    """Whether every id of ``ids`` is a canonical UUID string (lower-case hex digits, dashes
    after the 8th, 12th, 16th and 20th). Each id must be 36 characters long, as every caller
    has them (:class:`_Framed`'s decoder, the lake's column check): the joined text is then cut
    at every 36th character, its dashes found at those places of every id, the rest read as hex
    digits and written back to the same text (so no upper case, no blank, no other dash), in C
    over the whole block rather than a step per id. ``tests/events/test_envelope.py`` holds it
    to the regex of the UUID's spelling."""
    n = len(ids)
    text = "".join(ids)
    dashes = "-" * n
    for at in _DASHES:
        if text[at::36] != dashes:
            return False
    digits = text.replace("-", "")
    if len(digits) != 32 * n:
        return False
    try:
        return bytes.fromhex(digits).hex() == digits
    except ValueError:
        return False


def _plain_dict(payload: Mapping[str, Any]) -> dict[str, Any]:
    kind = type(payload)
    if kind is ReadPayload or kind is MappingProxyType:
        return payload.copy()  # type: ignore[attr-defined,no-any-return]  # in C, not key by key
    return dict(payload)


_FIELD_SET: Final = frozenset(ENVELOPE_FIELDS)
_SCALAR_FIELDS: Final = tuple(name for name in ENVELOPE_FIELDS if name != "payload")


def _plausible_envelope(d: dict[str, Any]) -> bool:
    """:func:`_plausible` of a dict's envelope fields (values straight from ``json.loads``)."""
    return _plausible(
        d["event_id"],
        d["stream"],
        d["seq"],
        d["time_ns"],
        d["recorded_at_ns"],
        d["type"],
        d["version"],
        d["task_id"],
    )


def _plausible(
    event_id: Any,
    stream: Any,
    seq: Any,
    time_ns: Any,
    recorded_at_ns: Any,
    event_type: Any,
    version: Any,
    task_id: Any,
) -> bool:
    """check_envelope's rules with exact types (plain str and int): True means valid; False lets
    :func:`check_envelope` look closer (an int subclass passes there) and word the error."""
    return (
        type(event_id) is str
        and _is_canonical_uuid(event_id)
        and type(stream) is str
        and stream != ""
        and type(seq) is int
        and seq >= 1
        and type(time_ns) is int
        and time_ns >= 0
        and type(recorded_at_ns) is int
        and recorded_at_ns >= 0
        and type(event_type) is str
        and event_type != ""
        and type(version) is int
        and version >= 1
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
    if _plausible(event_id, stream, seq, time_ns, recorded_at_ns, type, version, task_id):
        return  # every event built in Python, every append: one pass, no isinstance
    problem: tuple[str, object, str] | None = None
    if not (isinstance(event_id, str) and _is_canonical_uuid(event_id)):
        problem = ("event_id", event_id, "is not a canonical UUID string")
    elif not (isinstance(stream, str) and stream):
        problem = ("stream", stream, "is not a non-empty string")
    elif not (_is_int(seq) and seq >= 1):
        problem = ("seq", seq, "is not an integer >= 1")
    elif not (_is_int(time_ns) and time_ns >= 0):
        problem = ("time_ns", time_ns, "is not an integer >= 0")
    elif not (
        isinstance(recorded_at_ns, int)
        and not isinstance(recorded_at_ns, bool)
        and recorded_at_ns >= 0
    ):
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
_HEX_DIGITS: Final = b"0123456789abcdef"


def _is_canonical_uuid(value: str) -> bool:
    """Whether ``value`` matches :data:`_CANONICAL_UUID` (the test holds the two to the same set),
    with str and bytes methods: 36 ASCII characters, dashes at 8, 13, 18 and 23, and nothing but
    those four dashes left once the lower-case hex digits are deleted."""
    return (
        len(value) == 36
        and value[8] == value[13] == value[18] == value[23] == "-"
        and value.isascii()
        and value.encode().translate(None, _HEX_DIGITS) == b"----"
    )


def require_mapping(payload: object, event_type: str, version: int) -> None:
    if not isinstance(payload, Mapping):
        raise InvalidEventError(
            f"invalid {event_type} v{version} event: payload: "
            f"{type(payload).__name__} is not a JSON object (mapping)",
            event_type=event_type,
            version=version,
            path="payload",
            reason="not a mapping",
        )


#: A payload's JSON as a record holds it (compact, sorted keys, UTF-8 left as is).
_dumps_payload: Final = json.JSONEncoder(
    sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False
).encode


def json_payload(
    payload: Mapping[str, Any], event_type: str, version: int
) -> tuple[dict[str, Any], str]:
    """A payload as :class:`Event` keeps it (a deep copy in JSON types, :func:`_json_copy`) and
    its JSON text as a record holds it: what an append needs, in C when it can be.

    The fast path dumps the caller's dict with ``json`` and decodes the text back (msgspec): a
    fresh deep copy in JSON types. It is taken only if that copy equals the payload, which a
    payload ``_json_copy`` would refuse or change never does (a non-string key comes back a
    string, a tuple a list; NaN, a numpy integer, another mapping or object make ``json``
    raise). Everything else takes ``_json_copy``, its normalisation and its errors. The text
    is the same either way (``tests/events/test_envelope.py`` holds the two paths equal).
    """
    if type(payload) is dict:
        try:
            text = _dumps_payload(payload)
            copied = _decode_payload(text)
        except (TypeError, ValueError, msgspec.MsgspecError):
            pass
        else:
            if copied == payload:
                return copied, text
    copied = _json_copy(payload, "payload", event_type, version)
    try:
        return copied, _dumps_payload(copied)
    except ValueError as exc:  # a mapping that says it is a dict and is not: word it as json does
        raise InvalidEventError(
            f"invalid {event_type} v{version} event: payload: cannot be stored as JSON: {exc}",
            event_type=event_type,
            version=version,
            reason=str(exc),
        ) from exc


def _json_copy(value: Any, path: str, event_type: str, version: int) -> Any:
    """A deep copy restricted to JSON types: what ``json.dumps`` then ``json.loads`` would give.

    Normalising here (tuple → list, numpy scalar → int/float) keeps an appended event equal to
    the same event read back; refusing NaN/inf and non-JSON objects here keeps them off disk.
    """
    kind = type(value)
    if kind is dict:  # the common case first, scalars inline: a path is spelled out only
        out: dict[str, Any] = {}  # for a value that needs a closer look (every append)
        for key, item in value.items():
            if type(key) is not str:
                if not isinstance(key, str):
                    _not_json(key, path, event_type, version, "is not a string key")
                key = str.__str__(key)
            item_kind = type(item)
            if (
                item_kind is str
                or item_kind is int
                or item_kind is bool
                or item is None
                or (item_kind is float and math.isfinite(item))
            ):
                out[key] = item
            else:
                out[key] = _json_copy(item, f"{path}.{key}", event_type, version)
        return out
    if kind is list or kind is tuple:
        copied = []
        for i, item in enumerate(value):
            item_kind = type(item)
            if (
                item_kind is str
                or item_kind is int
                or item_kind is bool
                or item is None
                or (item_kind is float and math.isfinite(item))
            ):
                copied.append(item)
            else:
                copied.append(_json_copy(item, f"{path}[{i}]", event_type, version))
        return copied
    if value is None or kind in (str, int, bool):
        return value
    if kind is float:
        if not math.isfinite(value):
            _not_json(value, path, event_type, version, "is not a finite number")
        return value
    if isinstance(value, Mapping):
        return _json_copy(dict(value.items()), path, event_type, version)
    if isinstance(value, list | tuple):
        return _json_copy(list(value), path, event_type, version)
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
