from __future__ import annotations

import enum
import json
import uuid
import zlib
from types import MappingProxyType
from typing import Any

import msgspec
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from objsearch.events import EVENT_ID_NAMESPACE, Event, InvalidEventError, deterministic_event_id
from objsearch.events.envelope import check_envelope, event_ids, json_payload, require_mapping


def make_event(**overrides: Any) -> Event:
    fields: dict[str, Any] = {
        "event_id": deterministic_event_id("run-1", 1),
        "stream": "run-1",
        "seq": 1,
        "time_ns": 1_000,
        "recorded_at_ns": 2_000,
        "type": "search_failed",
        "version": 1,
        "task_id": "task-1",
        "payload": {"reason": "nothing left", "nested": {"list": [1, 2.5, None, True]}},
    }
    fields.update(overrides)
    return Event(**fields)


class Colour(enum.StrEnum):
    RED = "red"


# --- deterministic ids -------------------------------------------------------------------------


def test_deterministic_event_id_is_stable_across_processes_and_versions() -> None:
    # A golden value: if this changes, every id already written without an explicit id changes.
    assert deterministic_event_id("run-1", 1) == str(
        uuid.uuid5(uuid.UUID("d5d2c2b6-eb95-54bd-bb91-8142ed50e621"), "run-1/1")
    )
    assert uuid.uuid5(uuid.NAMESPACE_URL, "urn:objsearch:events") == EVENT_ID_NAMESPACE


def test_deterministic_event_id_depends_on_stream_and_seq_only() -> None:
    assert deterministic_event_id("a", 1) == deterministic_event_id("a", 1)
    ids = {deterministic_event_id(s, q) for s in ("a", "b") for q in (1, 2)}
    assert len(ids) == 4
    assert uuid.UUID(deterministic_event_id("a", 1)).version == 5


# --- construction and immutability ------------------------------------------------------------


def test_json_round_trip_gives_an_equal_event() -> None:
    event = make_event()
    d = event.to_json_dict()
    assert json.loads(json.dumps(d)) == d
    assert Event.from_json_dict(json.loads(json.dumps(d))) == event


def test_event_is_frozen() -> None:
    event = make_event()
    with pytest.raises(AttributeError):
        event.seq = 2  # type: ignore[misc, unused-ignore]


def test_payload_is_a_read_only_deep_copy() -> None:
    payload: dict[str, Any] = {"reason": "x", "nested": {"list": [1, 2]}}
    event = make_event(payload=payload)
    payload["reason"] = "changed"
    payload["nested"]["list"].append(3)
    assert event.payload == {"reason": "x", "nested": {"list": [1, 2]}}
    with pytest.raises(TypeError):
        event.payload["reason"] = "y"  # type: ignore[index, unused-ignore]


def test_to_json_dict_returns_a_copy_the_caller_may_change() -> None:
    event = make_event()
    d = event.to_json_dict()
    d["payload"]["nested"]["list"].clear()
    assert event.payload["nested"]["list"] == [1, 2.5, None, True]


def test_payload_is_normalised_to_json_types() -> None:
    event = make_event(
        payload={
            "point": (1.0, 2.0),
            "f": np.float64(0.5),
            "i": np.int64(3),
            "colour": Colour.RED,
            "proxy": {"inner": (1,)},
        }
    )
    assert event.payload == {
        "point": [1.0, 2.0],
        "f": 0.5,
        "i": 3,
        "colour": "red",
        "proxy": {"inner": [1]},
    }
    assert type(event.payload["i"]) is int
    assert type(event.payload["f"]) is float
    assert type(event.payload["colour"]) is str


@pytest.mark.parametrize(
    ("payload", "path"),
    [
        ({"x": float("nan")}, "payload.x"),
        ({"x": [1, float("inf")]}, "payload.x[1]"),
        ({"x": {1, 2}}, "payload.x"),
        ({"x": {1: "a"}}, "payload.x"),
        ({"x": np.zeros(2)}, "payload.x"),
        ({"x": b"bytes"}, "payload.x"),
    ],
)
def test_non_json_payload_values_are_refused_with_their_path(payload: Any, path: str) -> None:
    with pytest.raises(InvalidEventError, match=r"invalid search_failed v1 event: ") as info:
        make_event(payload=payload)
    assert info.value.path == path
    assert path in str(info.value)


def test_payload_must_be_a_mapping() -> None:
    with pytest.raises(InvalidEventError, match="payload: list is not a JSON object"):
        make_event(payload=[1, 2])


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("event_id", "not-a-uuid"),
        ("event_id", "F4F495F4-BA2B-4D82-87A9-C72642F7251B"),
        ("event_id", 5),
        ("stream", ""),
        ("stream", None),
        ("seq", 0),
        ("seq", True),
        ("seq", "1"),
        ("seq", 1.0),
        ("time_ns", -1),
        ("time_ns", 1.5),
        ("recorded_at_ns", None),
        ("type", ""),
        ("version", 0),
        ("task_id", ""),
        ("task_id", 3),
    ],
)
def test_bad_envelope_fields_are_refused_by_name(field: str, value: Any) -> None:
    with pytest.raises(InvalidEventError, match=rf"invalid event envelope: {field}: ") as info:
        make_event(**{field: value})
    assert info.value.path == field


def test_task_id_may_be_none() -> None:
    assert make_event(task_id=None).task_id is None


def test_from_json_dict_requires_exactly_the_envelope_fields() -> None:
    d = make_event().to_json_dict()
    del d["seq"]
    d["extra"] = 1
    with pytest.raises(InvalidEventError, match=r"missing field\(s\) 'seq'; unknown field\(s\)"):
        Event.from_json_dict(d)


def test_equal_events_hash_equal() -> None:
    a, b = make_event(), make_event()
    assert a == b
    assert hash(a) == hash(b)
    assert len({a, b}) == 1
    assert make_event(seq=2) != a


@given(st.text(min_size=1), st.integers(min_value=1, max_value=2**63 - 1))
def test_deterministic_ids_are_uuid5_of_stream_and_seq(stream: str, seq: int) -> None:
    expected = str(uuid.uuid5(EVENT_ID_NAMESPACE, f"{stream}/{seq}"))
    assert deterministic_event_id(stream, seq) == expected


@pytest.mark.parametrize("run", ["7a0c1a0e-7d1c-4c55-9a8f-2f1d3c4b5a69", "run-1", "h\u00e9/\u2028"])
def test_a_writers_default_ids_are_deterministic_event_id_over_many_seqs(run: str) -> None:
    """``event_ids(run)`` (the prefix hashed once, each id formatted from the digest) gives the
    very strings ``uuid.uuid5`` gives, for every seq of a long log and for huge ones."""
    event_id = event_ids(run)
    seqs = [*range(1, 20_001), 10**6, 2**31, 2**63 - 1, 10**30]
    for seq in seqs:
        expected = str(uuid.uuid5(EVENT_ID_NAMESPACE, f"{run}/{seq}"))
        assert event_id(seq) == expected == deterministic_event_id(run, seq)


# --- the canonical-id check --------------------------------------------------------------------

_ID_ALPHABET = "0123456789abcdefABCDEF-g{}_ 0\u0660\uff10\u00e9\n"


def _near_uuids() -> st.SearchStrategy[str]:
    """Canonical ids, ids with a character or two changed, cut or lengthened, and any text."""
    canonical = st.uuids().map(str)

    def mutate(draw_id: tuple[str, list[tuple[int, str]], int]) -> str:
        text, changes, cut = draw_id
        chars = list(text)
        for index, char in changes:
            chars[index % len(chars)] = char
        mutated = "".join(chars)
        return mutated[: len(mutated) + cut] if cut < 0 else mutated + "a" * cut

    edits = st.lists(st.tuples(st.integers(0, 35), st.sampled_from(_ID_ALPHABET)), max_size=2)
    return st.one_of(
        canonical,
        st.tuples(canonical, edits, st.integers(-2, 2)).map(mutate),
        st.text(alphabet=_ID_ALPHABET, min_size=34, max_size=38),
        st.text(),
    )


@given(_near_uuids())
def test_the_canonical_id_check_accepts_exactly_what_the_regex_does(value: str) -> None:
    from objsearch.events.envelope import (
        _CANONICAL_UUID,
        _is_canonical_uuid,
        canonical_ids,
        decode_event,
        frame_event,
    )

    canonical = _CANONICAL_UUID.fullmatch(value) is not None
    assert _is_canonical_uuid(value) == canonical
    # The decoder checks the id in its own (inlined) copy of the check: the same set.
    body = json.dumps({**make_event().to_json_dict(), "event_id": value}).encode()
    try:
        decode_event(body)
    except msgspec.ValidationError:
        accepted = False
    else:
        accepted = True
    assert accepted == canonical
    # A verifying scan's decoder checks only the length; the scan checks the ids in batches.
    try:
        frame_event(body)
    except msgspec.ValidationError:
        assert len(value) != 36
    else:
        assert len(value) == 36
        good = make_event().event_id
        assert canonical_ids([good, value, good]) == canonical
        assert canonical_ids([value]) == canonical


@pytest.mark.parametrize(
    "event_id", ["9A7A282D-F8E0-44CF-AD97-6BEC939D9A94", "0" * 36, "{" + "0" * 34 + "}"]
)
def test_a_record_with_a_non_canonical_id_is_refused_when_read(event_id: str) -> None:
    from objsearch.events.record import RecordError, decode_record, encode_record

    good = encode_record(make_event())
    line = good[:-1].replace(make_event().event_id.encode(), event_id.encode())
    body = line.rpartition(b"\t")[0]
    line = body + b"\t%08x" % zlib.crc32(body)
    with pytest.raises(RecordError, match="event_id"):
        decode_record(line)


# --- an append's payload: copied and dumped once ----------------------------------------------

_scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(),
    st.sampled_from([np.float64(0.25), np.int64(3), Colour.RED, b"bytes"]),
)
_values = st.recursive(
    _scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=3),
        st.lists(inner, max_size=3).map(tuple),
        st.dictionaries(st.text(max_size=4), inner, max_size=3),
        st.dictionaries(st.one_of(st.integers(0, 3), st.booleans()), inner, max_size=2),
    ),
    max_leaves=12,
)


def _appended(payload: Any, envelope: dict[str, Any]) -> tuple[Event, dict[str, Any], str]:
    """An append's event, payload copy and text, as ``Store.encode`` and the log make them (the
    schema check aside: these types have no schema)."""
    require_mapping(payload, envelope["type"], envelope["version"])
    copied, text = json_payload(payload, envelope["type"], envelope["version"])
    check_envelope(**envelope)
    return Event._appended(MappingProxyType(copied), **envelope), copied, text


@given(
    st.dictionaries(st.text(max_size=6), _values, max_size=5),
    st.text(min_size=1, max_size=8),
    st.one_of(st.none(), st.text(min_size=1, max_size=8)),
    st.integers(min_value=0, max_value=2**32 - 1),
)
def test_an_appended_event_is_built_and_encoded_as_event_and_encode_record_do(
    payload: dict[str, Any], stream: str, task_id: str | None, prev: int
) -> None:
    """What an append does (``Store.encode``'s one copy and one dump, ``Event._appended``, then
    ``encode_new_record``) gives the event, the error and the record bytes that ``Event(...)`` +
    ``encode_record`` give."""
    from objsearch.events.record import encode_new_record, encode_record, frame_new_record

    envelope: dict[str, Any] = {
        "event_id": deterministic_event_id(stream, 1),
        "stream": stream,
        "seq": 1,
        "time_ns": 5,
        "recorded_at_ns": 7,
        "type": "a_type",
        "version": 1,
        "task_id": task_id,
    }
    try:
        expected = Event(**envelope, payload=payload)
    except InvalidEventError as exc:
        with pytest.raises(InvalidEventError) as info:
            _appended(payload, envelope)
        assert str(info.value) == str(exc)
        assert info.value.path == exc.path
        return
    event, copied, text = _appended(payload, envelope)
    assert event == expected
    assert copied == dict(expected.payload)
    assert json.dumps(copied, sort_keys=True) == json.dumps(dict(expected.payload), sort_keys=True)
    assert encode_new_record(event, text, prev) == encode_record(expected, prev)
    # The checksum the writer keeps is the one the line carries (not read back from its digits).
    line, checksum = frame_new_record(event, text, prev)
    assert line == encode_record(expected, prev)
    assert checksum == int(line[-9:-1], 16)


@given(
    st.text(min_size=1, max_size=6),
    st.lists(
        st.tuples(
            st.sampled_from(["a_type", 'a "quoted" type', "t\u00e9\n"]),
            st.one_of(st.none(), st.sampled_from(["task-1", "task-2", 'q"\\', "\u2028"])),
        ),
        min_size=1,
        max_size=8,
    ),
)
def test_a_writers_framer_frames_each_record_as_encode_record_does(
    stream: str, envelopes: list[tuple[str, str | None]]
) -> None:
    """One writer's :class:`Framer` escapes its stream, each type and the last task id once and
    reuses them: every line it frames, task ids changing, repeating and going back to None, is
    the line ``encode_record`` writes for the same event, and its checksum chains."""
    from objsearch.events.record import Framer, encode_record

    framer = Framer(stream)
    prev = 0
    for seq, (event_type, task_id) in enumerate(envelopes, 1):
        event = Event(
            event_id=deterministic_event_id(stream, seq),
            stream=stream,
            seq=seq,
            time_ns=seq,
            recorded_at_ns=7,
            type=event_type,
            version=1,
            task_id=task_id,
            payload={"n": seq},
        )
        line, checksum = framer.frame(event, f'{{"n":{seq}}}', prev)
        assert line == encode_record(event, prev)
        assert checksum == int(line[-9:-1], 16)
        # A typed record's payload comes as UTF-8 bytes: framed as bytes, the same line.
        assert framer.frame(event, f'{{"n":{seq}}}'.encode(), prev) == (line, checksum)
        prev = checksum


@pytest.mark.parametrize("where", ["task_id", "type", "stream"])
def test_a_lone_surrogate_around_a_records_bytes_is_refused_as_the_str_path_refuses_it(
    where: str,
) -> None:
    """A payload made as bytes framed in an envelope that cannot be UTF-8 (a lone surrogate in
    the task id, the type or the stream) is refused with the words of the str path."""
    from objsearch.events.record import Framer

    fields = {"stream": "s", "type": "a_type", "task_id": "task-1", where: "x\udc80"}
    event = Event(
        event_id=deterministic_event_id("s", 1),
        seq=1,
        time_ns=1,
        recorded_at_ns=7,
        version=1,
        payload={"n": 1},
        **fields,
    )
    with pytest.raises(InvalidEventError) as from_str:
        Framer(fields["stream"]).frame(event, '{"n":1}', 0)
    with pytest.raises(InvalidEventError) as from_bytes:
        Framer(fields["stream"]).frame(event, b'{"n":1}', 0)
    assert str(from_bytes.value) == str(from_str.value)
    assert "surrogates not allowed" in str(from_bytes.value)


def test_an_appended_payload_with_a_lone_surrogate_is_refused_as_before() -> None:
    from objsearch.events.record import encode_new_record, encode_record

    expected = make_event(payload={"x": "\ud800"})
    event, _, text = _appended({"x": "\ud800"}, {
        name: getattr(expected, name) for name in ("event_id", "stream", "seq", "time_ns",
        "recorded_at_ns", "type", "version", "task_id")
    })  # fmt: skip
    with pytest.raises(InvalidEventError) as old:
        encode_record(expected)
    with pytest.raises(InvalidEventError) as new:
        encode_new_record(event, text)
    assert str(new.value) == str(old.value)
