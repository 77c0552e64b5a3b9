"""Appending a typed record stores the bytes an append of its payload dict stores, or takes that
path: every record the catalogue's schemas allow, floats of every magnitude, and records that
do not fit their type."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import msgspec
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from objsearch.agent.catalogue import LATEST, RECORDS, STORE, Moved, PlanarPose, decode
from objsearch.events import DuplicateEventError, EventLog, InvalidEventError, read_log
from objsearch.events.record_json import RecordCodec

from .schema_payloads import payloads

_SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
POSE = PlanarPose(x=1.0, y=2.0, yaw=0.0)


def _json(payload: Any) -> bytes:
    """What an append of the dict stores (events/envelope.py's ``_dumps_payload``)."""
    return json.dumps(
        payload, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False
    ).encode()


def _utf8(text: str | bytes) -> bytes:
    """An encoded payload's text as the bytes a record holds (a record's is made as bytes)."""
    return text if isinstance(text, bytes) else text.encode()


def _moved(metres: Any) -> Moved:
    return Moved(start=POSE, end=POSE, metres=metres, rooms=("kitchen",), interrupted=False)


@pytest.mark.parametrize("key", sorted(RECORDS), ids=[f"{t}-v{v}" for t, v in sorted(RECORDS)])
@_SETTINGS
@given(data=st.data())
def test_a_record_s_text_is_its_dict_s_text_or_none(key: tuple[str, int], data: Any) -> None:
    record_type = RECORDS[key]
    payload = data.draw(payloads(STORE.registry.schema(*key)), label="payload")
    try:
        record = msgspec.convert(payload, record_type, strict=True)
    except msgspec.ValidationError:
        return  # the schema allows what the record does not (the agreement test bounds this)
    codec = STORE.record_codec(record_type)
    assert (codec.type, codec.version) == key
    text = codec.payload_json(record)
    assert codec.payload(record) == json.loads(_json(codec.payload(record)))
    if text is not None:
        assert text == _json(codec.payload(record))
    # The one append path: what the store encodes for the record is what it encodes for its dict.
    encoded = STORE.encode_record(record)
    from_dict = STORE.encode(key[0], codec.payload(record), key[1])
    assert (encoded.type, encoded.version) == key
    assert _utf8(encoded.text) == _utf8(from_dict.text)
    assert dict(encoded.payload) == dict(from_dict.payload)


@_SETTINGS
@given(metres=st.floats(min_value=0, allow_nan=False, allow_infinity=False))
def test_floats_of_every_magnitude_are_spelt_as_json_spells_them(metres: float) -> None:
    record = _moved(metres)
    text = STORE.record_codec(Moved).payload_json(record)
    expected = _json(RecordCodec.payload(record))
    assert text is None or text == expected
    if metres != 0 and (metres < 1e-4 or metres >= 1e16):  # repr's exponent form
        assert text is None


def test_a_log_of_records_is_byte_for_byte_the_log_of_their_dicts(tmp_path: Path) -> None:
    records = [
        _moved(2.5),
        _moved(1e-7),  # spelt otherwise by msgspec: the dict path
        _moved(3.0e16),
        LATEST["search_failed"](reason="é \u2028 \x00 tab\there 1e5 :0.00001"),
    ]

    def bodies(directory: Path, use_records: bool) -> list[bytes]:
        with EventLog.open(directory, "s", store=STORE, wall_clock=lambda: 7) as log:
            for i, record in enumerate(records):
                event_id = f"00000000-0000-4000-8000-{i:012x}"  # default ids hold the run id
                if use_records:
                    log.append_record(record, time_ns=i, task_id="task-1", event_id=event_id)
                else:
                    payload = RecordCodec.payload(record)
                    log.append(record.TYPE, payload, time_ns=i, task_id="task-1", event_id=event_id)
        # The checksum chain starts from the log's run id: compare what it covers.
        raw = (directory / "events.log").read_bytes()
        return [line.rpartition(b"\t")[0] for line in raw.splitlines()]

    by_record = bodies(tmp_path / "records", True)
    assert by_record == bodies(tmp_path / "dicts", False)
    assert [json.loads(body)["payload"] for body in by_record] == [
        RecordCodec.payload(r) for r in records
    ]


def test_the_event_returned_reads_as_the_record(tmp_path: Path) -> None:
    record = _moved(2.5)
    with EventLog.open(tmp_path, "s", store=STORE) as log:
        event = log.append_record(record, time_ns=1, task_id="task-1")
    assert (event.type, event.version) == ("moved", LATEST["moved"].VERSION)
    assert decode(event, Moved) == record
    assert dict(event.payload) == RecordCodec.payload(record)
    assert list(read_log(tmp_path, store=STORE)) == [event]


@pytest.mark.parametrize("metres", [float("nan"), "two", -1.0], ids=["nan", "a string", "< 0"])
def test_a_record_that_does_not_fit_is_refused_as_its_dict_is(tmp_path: Path, metres: Any) -> None:
    record = _moved(metres)
    with EventLog.open(tmp_path / "r", "s", store=STORE) as log:
        with pytest.raises(InvalidEventError) as by_record:
            log.append_record(record, time_ns=1)
        assert log.last_seq == 0
    with (
        EventLog.open(tmp_path / "d", "s", store=STORE) as log,
        pytest.raises(InvalidEventError) as by_dict,
    ):
        log.append("moved", RecordCodec.payload(record), time_ns=1)
    assert str(by_record.value) == str(by_dict.value)
    assert (tmp_path / "r" / "events.log").read_bytes() == b""


def test_a_type_that_is_not_the_catalogue_s_record_is_refused(tmp_path: Path) -> None:
    class Stranger(msgspec.Struct, frozen=True):
        x: int

    with (
        EventLog.open(tmp_path, "s", store=STORE) as log,
        pytest.raises(InvalidEventError, match="Stranger is not a record of this store"),
    ):
        log.append_record(Stranger(x=1), time_ns=1)


def test_append_record_is_idempotent_by_event_id(tmp_path: Path) -> None:
    event_id = "00000000-0000-4000-8000-000000000001"
    with EventLog.open(tmp_path, "s", store=STORE) as log:
        first = log.append_record(_moved(1.0), time_ns=1, event_id=event_id)
        again = log.append_record(_moved(1.0), time_ns=1, event_id=event_id)
        assert again == first and log.last_seq == 1
        with pytest.raises(DuplicateEventError, match="payload"):
            log.append_record(_moved(2.0), time_ns=1, event_id=event_id)


def test_time_running_backwards_is_refused(tmp_path: Path) -> None:
    with EventLog.open(tmp_path, "s", store=STORE) as log:
        log.append_record(_moved(1.0), time_ns=5)
        with pytest.raises(InvalidEventError, match="before the last event"):
            log.append_record(_moved(1.0), time_ns=4)
        assert log.last_seq == 1
