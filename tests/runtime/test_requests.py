"""Every request and result type: valid documents read back as sent, each bad field is named."""

from __future__ import annotations

from typing import Any

import pytest

from objsearch.runtime.errors import MessageError
from objsearch.runtime.requests import (
    FindRequest,
    Heartbeat,
    RequestError,
    WhereRequest,
    check_find_result,
    check_reset_result,
    check_where_result,
    parse_document,
    parse_find_request,
    parse_heartbeat,
    parse_open_request,
    parse_open_result,
    parse_reset_request,
    parse_where_request,
    request_id,
)


def test_a_valid_find_request_reads_back() -> None:
    sent = FindRequest("f1", "Apple", "kitchen-1", 3, 1_700_000_000_000_000_000)
    assert parse_find_request(sent.to_json()) == sent
    assert parse_find_request({"id": "f2", "target": "Toilet paper"}) == FindRequest(
        "f2", "Toilet paper"
    )
    nulls = {"id": "f3", "target": "Cup", "start": None, "scene": None, "not_before_ns": None}
    assert parse_find_request(nulls) == FindRequest("f3", "Cup")


# The request that ended `objsearch agent run` (issue 12), and its relatives.
@pytest.mark.parametrize(
    ("text", "field"),
    [
        ('{"id":"f1","target":"Apple","scene":"abc"}', "scene"),
        ('{"id":"f1","target":"Apple","scene":[1]}', "scene"),
        ('{"id":"f1","target":"Apple","scene":NaN}', "scene"),
        ('{"id":"f1","target":"Apple","scene":1e400}', "scene"),
        ('{"id":"f1","target":"Apple","scene":-1}', "scene"),
        ('{"id":"f1","target":"Apple","scene":1.0}', "scene"),
        ('{"id":"f1","target":"Apple","scene":true}', "scene"),
        ('{"id":"f1","target":"Apple","scene":' + "9" * 5000 + "}", "scene"),
        ('{"id":"f1","target":"Apple","not_before_ns":"soon"}', "not_before_ns"),
        ('{"id":"f1","target":"Apple","not_before_ns":-Infinity}', "not_before_ns"),
        ('{"id":"f1","target":"Apple","not_before_ns":9223372036854775808}', "not_before_ns"),
        ('{"id":"f1","target":"' + "A" * 129 + '"}', "target"),
        ('{"id":"f1","target":"Apple\\n"}', "target"),
        ('{"id":"f1","target":null}', "target"),
        ('{"id":"f1"}', "target"),
        ('{"id":"f1","target":"Apple","start":"\\ud800"}', "start"),
        ('{"id":"f1","target":"Apple","start":7}', "start"),
        ('{"id":"f1","target":"Apple","Scene":1}', "Scene"),
    ],
)
def test_a_bad_field_is_named(text: str, field: str) -> None:
    doc = parse_document(text)
    assert request_id(doc) == "f1"  # answerable
    with pytest.raises(RequestError) as caught:
        parse_find_request(doc)
    assert caught.value.field == field
    assert f"field {field!r}" in str(caught.value)


@pytest.mark.parametrize(
    "text",
    [
        "",
        "[1]",
        "42",
        "NaN",
        '"find"',
        '{"id":"f1"',
        "[" * 5000 + "]" * 5000,
        '{"id":"f1","target":"' + "x" * 20_000 + '"}',
    ],
)
def test_a_document_that_is_not_an_object_is_refused(text: str) -> None:
    with pytest.raises(MessageError):
        parse_document(text)


@pytest.mark.parametrize("rid", [None, 5, "", "a b", "i" * 129, ["a"], {"id": "x"}, "\u00e9"])
def test_an_unusable_id_cannot_be_answered(rid: Any) -> None:
    with pytest.raises(MessageError, match="usable 'id'"):
        request_id({"id": rid, "target": "Apple"})


def test_open_and_reset_requests() -> None:
    assert parse_open_request({"id": "o", "static_id": "kitchen/Fridge|+01.0|0"}).static_id
    with pytest.raises(RequestError, match="'static_id'"):
        parse_open_request({"id": "o", "static_id": 3})
    assert parse_reset_request({"id": "r", "scene": None, "start": "kitchen-1"}).scene is None
    with pytest.raises(RequestError, match="'scene'"):
        parse_reset_request({"id": "r", "scene": "1", "start": "kitchen-1"})
    with pytest.raises(RequestError, match="'start'"):
        parse_reset_request({"id": "r", "scene": 1})


def test_results() -> None:
    ok = parse_open_result({"id": "o", "ok": True, "stamp_ns": 5, "yaw": 1.5})
    assert (ok.ok, ok.stamp_ns, ok.yaw) == (True, 5, 1.5)
    assert parse_open_result({"id": "o", "ok": False, "error": "stuck"}).error == "stuck"
    for bad, field in [
        ({"id": "o", "ok": True, "stamp_ns": "5", "yaw": 0.0}, "stamp_ns"),
        ({"id": "o", "ok": True, "stamp_ns": 5, "yaw": float("nan")}, "yaw"),
        ({"id": "o", "ok": "yes"}, "ok"),
    ]:
        with pytest.raises(RequestError) as caught:
            parse_open_result(bad)  # type: ignore[arg-type]
        assert caught.value.field == field
    found = {
        "id": "f",
        "ok": True,
        "target": "Apple",
        "task_id": "task-00001",
        "success": True,
        "path_length": 3.5,
        "found": "kitchen/Apple|1|2",
        "plans": [["kitchen", ["a", "b"]]],
    }
    assert check_find_result(found) == found
    with pytest.raises(RequestError, match="'plans'"):
        check_find_result({**found, "plans": [["kitchen", "a"]]})
    with pytest.raises(RequestError, match="'error'"):
        check_find_result({"id": "f", "ok": False})
    assert check_reset_result({"id": "r", "ok": True, "stamp_ns": 0})["ok"]
    with pytest.raises(RequestError, match="'stamp_ns'"):
        check_reset_result({"id": "r", "ok": True, "stamp_ns": -1})


def test_where_request_and_result() -> None:
    assert parse_where_request({"id": "w", "target": "Cup"}) == WhereRequest("w", "Cup")
    cases: list[tuple[dict[str, Any], str]] = [
        ({"id": "w"}, "target"),
        ({"id": "w", "target": 7}, "target"),
        ({"id": "w", "target": "Cup", "scene": 1}, "scene"),
    ]
    for bad, field in cases:
        with pytest.raises(RequestError) as caught:
            parse_where_request(bad)
        assert caught.value.field == field
    answer = {
        "target": "Cup",
        "tasks": 3,
        "last_seen": None,
        "usually": None,
        "most_likely_now": [],
    }
    ok = {"id": "w", "ok": True, "answer": answer}
    assert check_where_result(ok) == ok
    assert not check_where_result({"id": "w", "ok": False, "error": "unknown"})["ok"]
    for bad in (
        {"id": "w", "ok": True},
        {"id": "w", "ok": True, "answer": {"target": "Cup"}},
        {"id": "w", "ok": True, "answer": {**answer, "last_seen": "kitchen"}},
    ):
        with pytest.raises(RequestError, match="'answer'"):
            check_where_result(bad)
    with pytest.raises(RequestError, match="'error'"):
        check_where_result({"id": "w", "ok": False})


def test_heartbeats() -> None:
    beat = Heartbeat(
        "a1", "objsearch", "robot-pc", 7, "/logs/é", "serving", 5, ("/objsearch/find",)
    )
    assert parse_heartbeat(beat.to_json()) == beat
    cases: list[tuple[dict[str, Any], str]] = [
        ({"agent": "a b"}, "agent"),
        ({"pid": -1}, "pid"),
        ({"state": "yielding"}, "state"),
        ({"log": "x\x1b[2J"}, "log"),
        ({"serves": []}, "serves"),
        ({"serves": ["/objsearch/find", "no spaces"]}, "serves"),
        ({"since_ns": 1.5}, "since_ns"),
        ({"extra": 1}, "extra"),
    ]
    for change, field in cases:
        with pytest.raises(RequestError) as caught:
            parse_heartbeat({**beat.to_json(), **change})
        assert caught.value.field == field
