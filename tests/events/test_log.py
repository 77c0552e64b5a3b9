from __future__ import annotations

import json
import logging
import os
import re
import uuid
import warnings
import zlib
from pathlib import Path
from typing import Any

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import (
    CorruptLogError,
    Event,
    EventLog,
    EventStoreError,
    InvalidEventError,
    LogClosedError,
    LogNotFoundError,
    StreamMismatchError,
    TornTailWarning,
    read_log,
)

from .payloads import EXAMPLES

STREAM = "run-1"
RUN = "00000000-0000-4000-8000-0000000000aa"
LINE = re.compile(rb"^(\{[^\t\n]*\})\t([0-9a-f]{8})\n$")


def open_log(directory: Path, stream: str = STREAM, **kwargs: Any) -> EventLog:
    kwargs.setdefault("wall_clock", lambda: 42)
    kwargs.setdefault("run_id", RUN)
    return EventLog.open(directory, stream, **kwargs, store=STORE)


def write_events(
    directory: Path, n: int, stream: str = STREAM, *, crash_after: int | None = None
) -> list[Event]:
    """Append ``n`` events; with ``crash_after``, close cleanly after that many and die (as a
    SIGKILL would: no close, no high-water mark) after the rest."""
    if crash_after is not None:
        return write_events(directory, crash_after, stream) + crash_after_appending(
            directory, n - crash_after, stream, first=crash_after
        )
    with open_log(directory, stream) as log:
        return [log.append("search_failed", {"reason": f"r{i}"}, time_ns=i) for i in range(n)]


def crash_after_appending(directory: Path, n: int, stream: str, *, first: int = 0) -> list[Event]:
    log = open_log(directory, stream)
    events = [
        log.append("search_failed", {"reason": f"r{i}"}, time_ns=i) for i in range(first, first + n)
    ]
    abandon(log)
    return events


def abandon(log: EventLog) -> None:
    """What a killed writer leaves: its descriptors closed by the kernel, nothing else done."""
    os.close(log._fd)
    os.close(log._lock_fd)
    log._closed = True


def lines(directory: Path) -> list[bytes]:
    return (directory / "events.log").read_bytes().splitlines(keepends=True)


def record_line(envelope: dict[str, Any], after: bytes) -> bytes:
    """A well-formed line whose checksum chains onto the line ``after``, whatever it says."""
    body = json.dumps(envelope, sort_keys=True, separators=(",", ":")).encode()
    return body + b"\t%08x\n" % zlib.crc32(body, int(after[-9:-1], 16))


# --- round trip, format, sequence ---------------------------------------------------------------


def test_records_are_compact_sorted_json_with_a_crc(tmp_path: Path) -> None:
    write_events(tmp_path, 3)
    for raw in lines(tmp_path):
        match = LINE.match(raw)
        assert match is not None, raw
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert meta == {"format": "objsearch.events/2", "stream": STREAM, "run_id": RUN}
    # The chain starts from the log's genesis (format, stream, run id) and each checksum
    # continues from the previous one.
    prev = zlib.crc32(f"objsearch.events/2\n{STREAM}\n{RUN}\n".encode())
    for raw in lines(tmp_path):
        match = LINE.match(raw)
        assert match is not None, raw
        body, crc = match.groups()
        assert int(crc, 16) == zlib.crc32(body, prev)
        prev = int(crc, 16)
        envelope = json.loads(body)
        assert body == json.dumps(envelope, sort_keys=True, separators=(",", ":")).encode()


def test_unicode_line_separators_in_payloads_do_not_split_records(tmp_path: Path) -> None:
    reason = "caf\u00e9 \u2028 line\u2029 sep \t tab \n newline"
    with open_log(tmp_path) as log:
        log.append("search_failed", {"reason": reason}, time_ns=1)
        log.append("search_failed", {"reason": "next"}, time_ns=2)
    assert [e.payload["reason"] for e in read_log(tmp_path, store=STORE)] == [reason, "next"]
    assert len(lines(tmp_path)) == 2
    assert "café".encode() in lines(tmp_path)[0]  # UTF-8, not \\u escapes


def test_same_inputs_give_byte_identical_logs(tmp_path: Path) -> None:
    for name in ("a", "b"):
        with open_log(tmp_path / name) as log:
            for i, (t, p) in enumerate(EXAMPLES.items()):
                log.append(t, p, time_ns=i)
    assert (tmp_path / "a" / "events.log").read_bytes() == (
        tmp_path / "b" / "events.log"
    ).read_bytes()


def test_explicit_event_id_and_version_are_kept(tmp_path: Path) -> None:
    event_id = "00000000-0000-4000-8000-000000000001"
    with open_log(tmp_path) as log:
        event = log.append(
            "search_failed", {"reason": "x"}, time_ns=1, version=1, event_id=event_id
        )
    assert event.event_id == event_id
    assert next(read_log(tmp_path, store=STORE)).event_id == event_id


def test_read_range(tmp_path: Path) -> None:
    write_events(tmp_path, 6)
    assert [e.seq for e in read_log(tmp_path, from_seq=3, store=STORE)] == [3, 4, 5, 6]
    assert [e.seq for e in read_log(tmp_path, from_seq=2, to_seq=4, store=STORE)] == [2, 3, 4]
    assert list(read_log(tmp_path, from_seq=5, to_seq=4, store=STORE)) == []
    assert list(read_log(tmp_path, from_seq=9, store=STORE)) == []
    with pytest.raises(ValueError, match="from_seq must be an integer >= 1"):
        read_log(tmp_path, from_seq=0, store=STORE)


def test_a_new_log_is_empty(tmp_path: Path) -> None:
    with open_log(tmp_path / "new") as log:
        assert log.last_seq == 0
    assert list(read_log(tmp_path / "new", store=STORE)) == []
    # A crash between writing meta.json and creating events.log leaves an empty log, not an error.
    (tmp_path / "new" / "events.log").unlink()
    assert list(read_log(tmp_path / "new", store=STORE)) == []
    with open_log(tmp_path / "new", create=False) as log:
        assert log.append("search_failed", {"reason": "x"}, time_ns=0).seq == 1


# --- validation before writing ----------------------------------------------------------------


@pytest.mark.parametrize(
    ("event_type", "payload", "kwargs", "message"),
    [
        (
            "task_started",
            dict(EXAMPLES["task_started"], target=3),
            {},
            "invalid task_started v2 event: payload.target: 3 is not of type 'string'",
        ),
        ("teleported", {}, {}, "unknown event type 'teleported'; known types: container_opened"),
        ("moved", EXAMPLES["moved"], {"version": 9}, "unknown version 9 of event type 'moved'"),
        ("search_failed", {"reason": float("nan")}, {}, "payload.reason: nan"),
        ("search_failed", {"reason": "\ud800"}, {}, "cannot be stored as UTF-8 JSON"),
        ("search_failed", {"reason": "x"}, {"event_id": "nope"}, "event_id: 'nope'"),
        ("search_failed", {"reason": "x"}, {"time_ns": -5}, "time_ns: -5"),
        ("search_failed", {"reason": "x"}, {"task_id": ""}, "task_id: ''"),
        # Caller-given fields the writer's own check (issue 46) passes to the envelope's words.
        ("search_failed", {"reason": "x"}, {"time_ns": True}, "time_ns: True is not an integer"),
        ("search_failed", {"reason": "x"}, {"time_ns": 7.0}, "time_ns: 7.0 is not an integer"),
        ("search_failed", {"reason": "x"}, {"task_id": 5}, "task_id: 5 is neither null nor"),
        ("search_failed", {"reason": "x"}, {"version": True}, "version: True is not an integer"),
        # Only the repair writes a quarantine record that redirects the checksum chain.
        (
            "record_quarantined",
            dict(EXAMPLES["record_quarantined"], chain="0badc0de"),
            {},
            "payload.chain: only `objsearch log repair` redirects the checksum chain",
        ),
    ],
)
def test_invalid_events_are_refused_and_nothing_is_written(
    tmp_path: Path, event_type: str, payload: Any, kwargs: dict[str, Any], message: str
) -> None:
    write_events(tmp_path, 2)
    before = (tmp_path / "events.log").read_bytes()
    with open_log(tmp_path) as log:
        kwargs.setdefault("time_ns", 7)
        with pytest.raises(InvalidEventError, match=re.escape(message)):
            log.append(event_type, payload, **kwargs)
        assert (tmp_path / "events.log").read_bytes() == before
        assert log.last_seq == 2
        assert log.append("search_failed", {"reason": "ok"}, time_ns=8).seq == 3


@pytest.mark.parametrize("clock", [-1, 1.5, True])
def test_a_wall_clock_reading_that_is_no_time_is_refused_and_nothing_is_written(
    tmp_path: Path, clock: Any
) -> None:
    with EventLog.open(tmp_path, STREAM, wall_clock=lambda: clock, store=STORE) as log:
        with pytest.raises(InvalidEventError, match=re.escape(f"recorded_at_ns: {clock!r} is not")):
            log.append("search_failed", {"reason": "x"}, time_ns=1)
        assert log.last_seq == 0
    assert (tmp_path / "events.log").read_bytes() == b""


# --- torn tails --------------------------------------------------------------------------------


@pytest.mark.parametrize("keep", [1, 10, 0.5, -2, -1], ids=lambda k: f"keep={k}")
def test_torn_last_record_is_cut_on_open_kept_aside_and_warned(
    tmp_path: Path, keep: float, caplog: pytest.LogCaptureFixture
) -> None:
    write_events(tmp_path, 3, crash_after=2)
    data = (tmp_path / "events.log").read_bytes()
    last_start = len(data) - len(lines(tmp_path)[-1])
    last_len = len(data) - last_start
    cut_at = last_start + (int(last_len * keep) if isinstance(keep, float) else keep % last_len)
    assert last_start < cut_at < len(data)
    (tmp_path / "events.log").write_bytes(data[:cut_at])

    with (
        caplog.at_level(logging.WARNING, logger="objsearch.events.log"),
        pytest.warns(TornTailWarning) as record,
    ):
        log = open_log(tmp_path)
    message = str(record[0].message)
    assert str(tmp_path / "events.log") in message
    assert f"cut {cut_at - last_start} byte(s) at byte offset {last_start}" in message
    assert message in caplog.text
    with log:
        assert log.last_seq == 2
        assert log.torn_tail is not None and log.torn_tail.offset == last_start
        assert (tmp_path / "events.log").read_bytes() == data[:last_start]
        # Nothing is deleted: the cut bytes are kept beside the log, named in the warning.
        assert log.torn_tail.quarantine == tmp_path / f"events.log.torn-{last_start}"
        assert log.torn_tail.quarantine.read_bytes() == data[last_start:cut_at]
        assert str(log.torn_tail.quarantine) in message
        assert log.append("search_failed", {"reason": "after"}, time_ns=5).seq == 3
    assert [e.payload["reason"] for e in read_log(tmp_path, store=STORE)] == ["r0", "r1", "after"]


@pytest.mark.parametrize("garbage", [b"garbage without newline", b"\x00" * 300, b'{"half": "a rec'])
def test_an_unterminated_fragment_after_the_last_record_is_a_torn_tail(
    tmp_path: Path, garbage: bytes
) -> None:
    write_events(tmp_path, 2)
    good = (tmp_path / "events.log").read_bytes()
    (tmp_path / "events.log").write_bytes(good + garbage)
    with pytest.warns(TornTailWarning, match=f"cut {len(garbage)} byte"), open_log(tmp_path) as log:
        assert log.last_seq == 2
        log.append("search_failed", {"reason": "ok"}, time_ns=3)
    assert [e.seq for e in read_log(tmp_path, store=STORE)] == [1, 2, 3]
    assert (tmp_path / f"events.log.torn-{len(good)}").read_bytes() == garbage


@pytest.mark.parametrize("garbage", [b"bad\tffffffff\n", b"x\ny", b"\n"])
def test_a_complete_bad_line_at_the_end_is_corruption_not_a_torn_tail(
    tmp_path: Path, garbage: bytes
) -> None:
    write_events(tmp_path, 2)
    with (tmp_path / "events.log").open("ab") as f:
        f.write(garbage)
    _assert_corrupt(tmp_path, 3, "checksum")


def test_a_log_cut_before_its_high_water_mark_is_corruption(tmp_path: Path) -> None:
    write_events(tmp_path, 3)
    raw = lines(tmp_path)
    (tmp_path / "events.log").write_bytes(b"".join(raw[:2]))  # a clean cut at a record boundary
    _assert_corrupt(tmp_path, 3, "closed it at seq 3 .* acknowledged records are missing")
    (tmp_path / "events.log").write_bytes(b"".join(raw) + raw[2][:10])
    with pytest.warns(TornTailWarning):  # past the mark, an unterminated fragment is torn
        assert [e.seq for e in read_log(tmp_path, store=STORE)] == [1, 2, 3]
    (tmp_path / "events.log").write_bytes(b"".join(raw[:2]) + raw[2][:-1])
    _assert_corrupt(tmp_path, 3, "acknowledged records are missing")


def test_crlf_line_endings_are_corruption_and_named(tmp_path: Path) -> None:
    write_events(tmp_path, 3)
    crlf = (tmp_path / "events.log").read_bytes().replace(b"\n", b"\r\n")
    (tmp_path / "events.log").write_bytes(crlf)
    _assert_corrupt(tmp_path, 1, "CR LF")


def test_reader_skips_a_torn_tail_with_a_warning_and_changes_nothing(tmp_path: Path) -> None:
    write_events(tmp_path, 3, crash_after=2)
    torn = (tmp_path / "events.log").read_bytes()[:-7]
    (tmp_path / "events.log").write_bytes(torn)
    with pytest.warns(TornTailWarning, match="skipping .* the file was not changed"):
        events = list(read_log(tmp_path, store=STORE))
    assert [e.seq for e in events] == [1, 2]
    assert (tmp_path / "events.log").read_bytes() == torn


def test_reader_is_silent_about_an_append_in_progress(tmp_path: Path) -> None:
    write_events(tmp_path, 2)
    with open_log(tmp_path):
        # What a reader can see while the writer's write() is half done.
        with (tmp_path / "events.log").open("ab") as f:
            f.write(b'{"event_id":"partial')
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert [e.seq for e in read_log(tmp_path, store=STORE)] == [1, 2]


# --- corruption in the middle ------------------------------------------------------------------


def _assert_corrupt(tmp_path: Path, line: int, match: str) -> None:
    before = (tmp_path / "events.log").read_bytes()
    offset = sum(len(x) for x in lines(tmp_path)[: line - 1])
    with pytest.raises(CorruptLogError, match=match) as info:
        list(read_log(tmp_path, store=STORE))
    assert f"line {line} (byte offset {offset})" in str(info.value)
    assert (info.value.line, info.value.offset) == (line, offset)
    assert str(tmp_path / "events.log") in str(info.value)
    with pytest.raises(CorruptLogError, match=match):
        open_log(tmp_path)
    assert (tmp_path / "events.log").read_bytes() == before
    assert not list(tmp_path.glob("events.log.*"))  # nothing cut, nothing kept aside
    with pytest.raises(CorruptLogError):  # not LogLockedError: the failed open let go of the lock
        open_log(tmp_path)


def test_missing_newline_in_the_middle_is_corruption(tmp_path: Path) -> None:
    write_events(tmp_path, 4)
    raw = lines(tmp_path)
    raw[1] = raw[1][:-1]  # lines 2 and 3 merge into one damaged line
    (tmp_path / "events.log").write_bytes(b"".join(raw))
    _assert_corrupt(tmp_path, 2, "checksum mismatch")


@pytest.mark.parametrize("how", ["swap", "splice", "copy"])
def test_intact_records_out_of_place_break_the_chain(tmp_path: Path, how: str) -> None:
    write_events(tmp_path / "a", 4)
    # The same stream name, another run: before the chain, its records passed every check.
    with EventLog.open(tmp_path / "b", STREAM, wall_clock=lambda: 42, store=STORE) as other:
        for i in range(4):
            other.append("search_failed", {"reason": f"r{i}"}, time_ns=i)
    raw, donor = lines(tmp_path / "a"), lines(tmp_path / "b")
    if how == "swap":
        raw[1], raw[2] = raw[2], raw[1]
        line, match = 2, "a line out of place"
    elif how == "splice":
        raw = raw[:2] + donor[2:]
        line, match = 3, "spliced, reordered"
    else:
        raw = [*raw, donor[0]]
        line, match = 5, "spliced, reordered"
    (tmp_path / "a" / "events.log").write_bytes(b"".join(raw))
    _assert_corrupt(tmp_path / "a", line, match)


def test_seq_gap_is_corruption(tmp_path: Path) -> None:
    events = write_events(tmp_path, 3)
    raw = lines(tmp_path)
    skipped = dict(events[2].to_json_dict(), seq=5)
    (tmp_path / "events.log").write_bytes(b"".join(raw[:2]) + record_line(skipped, raw[1]))
    _assert_corrupt(tmp_path, 3, "expected seq 3, found seq 5")


def test_checksummed_but_invalid_record_is_corruption_even_at_the_end(tmp_path: Path) -> None:
    write_events(tmp_path, 2)
    body = b'{"not": "an envelope"'
    bad = body + b"\t%08x\n" % zlib.crc32(body, int(lines(tmp_path)[-1][-9:-1], 16))
    with (tmp_path / "events.log").open("ab") as f:
        f.write(bad)
    _assert_corrupt(tmp_path, 3, "checksum matches but the JSON is invalid")


def _append_forged(tmp_path: Path, envelope: dict[str, Any]) -> None:
    last = lines(tmp_path)[-1]
    with (tmp_path / "events.log").open("ab") as f:
        f.write(record_line(envelope, last))


def test_record_of_another_stream_is_corruption(tmp_path: Path) -> None:
    events = write_events(tmp_path, 2)
    _append_forged(tmp_path, dict(events[1].to_json_dict(), seq=3, stream="other"))
    _assert_corrupt(tmp_path, 3, "record of stream 'other' in the log of stream 'run-1'")


def test_record_missing_envelope_fields_is_corruption(tmp_path: Path) -> None:
    events = write_events(tmp_path, 1)
    partial = events[0].to_json_dict()
    partial["seq"] = 2
    del partial["time_ns"]
    _append_forged(tmp_path, partial)
    _assert_corrupt(tmp_path, 2, "missing field\\(s\\) 'time_ns'")


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"event_id": "not-a-uuid"}, "event_id"),
        ({"event_id": "0000000A-0000-4000-8000-000000000001"}, "event_id"),
        ({"version": 99}, "version 99 is not one this code knows"),
        ({"type": "teleported"}, "'teleported' version 1 is not one this code knows"),
        ({"time_ns": 0}, "time runs backwards"),
    ],
)
def test_envelopes_the_docs_forbid_are_corruption(
    tmp_path: Path, change: dict[str, Any], match: str
) -> None:
    events = write_events(tmp_path, 2)
    forged = dict(events[1].to_json_dict(), seq=3, time_ns=5, **{"event_id": str(uuid.uuid4())})
    _append_forged(tmp_path, {**forged, **change})
    _assert_corrupt(tmp_path, 3, match)


# --- opening: lock, stream, missing logs -------------------------------------------------------


def test_stream_mismatch_is_refused(tmp_path: Path) -> None:
    write_events(tmp_path, 1)
    with pytest.raises(StreamMismatchError, match="belongs to stream 'run-1', not 'run-2'"):
        open_log(tmp_path, "run-2")
    open_log(tmp_path / "empty").close()
    with pytest.raises(StreamMismatchError):
        open_log(tmp_path / "empty", "run-2")  # meta.json binds even an empty log


def test_missing_logs_raise_log_not_found(tmp_path: Path) -> None:
    missing = tmp_path / "missing"
    with pytest.raises(LogNotFoundError, match=r"no event log at .*missing.*does not exist"):
        open_log(missing, create=False)
    assert not missing.exists()
    with pytest.raises(FileNotFoundError):
        read_log(missing, store=STORE)  # raised at call time, not at the first next()
    missing.mkdir()
    with pytest.raises(LogNotFoundError, match=r"meta\.json is missing"):
        open_log(missing, create=False)
    assert list(missing.iterdir()) == []  # no LOCK left behind
    with pytest.raises(LogNotFoundError, match=r"meta\.json is missing"):
        read_log(missing, store=STORE)


def test_events_log_without_meta_is_not_adopted(tmp_path: Path) -> None:
    write_events(tmp_path, 1)
    (tmp_path / "meta.json").unlink()
    with pytest.raises(LogNotFoundError, match=r"meta.json is missing \(but events.log exists\)"):
        open_log(tmp_path)


def test_unknown_format_is_refused(tmp_path: Path) -> None:
    write_events(tmp_path, 1)
    (tmp_path / "meta.json").write_text('{"format": "objsearch.events/3", "stream": "run-1"}')
    with pytest.raises(EventStoreError, match=r"unsupported log format 'objsearch\.events/3'"):
        read_log(tmp_path, store=STORE)


def test_creates_missing_parent_directories(tmp_path: Path) -> None:
    write_events(tmp_path / "a" / "b" / "c", 1)
    assert [e.seq for e in read_log(tmp_path / "a" / "b" / "c", store=STORE)] == [1]


# --- durability: fsync, batches, failures ------------------------------------------------------


class FsyncCounter:
    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.calls = 0
        self._real = os.fsync
        monkeypatch.setattr(os, "fsync", self)

    def __call__(self, fd: int) -> None:
        self.calls += 1
        self._real(fd)


def test_each_append_is_fsynced_before_it_returns(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    with open_log(tmp_path) as log:
        counter = FsyncCounter(monkeypatch)
        for i in range(3):
            log.append("search_failed", {"reason": "x"}, time_ns=i)
            assert counter.calls == i + 1


def test_batch_fsyncs_once_at_exit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with open_log(tmp_path) as log:
        counter = FsyncCounter(monkeypatch)
        with log.batch():
            for i in range(10):
                log.append("search_failed", {"reason": "x"}, time_ns=i)
            with log.batch():  # nested: still one fsync, at the outermost exit
                log.append("search_failed", {"reason": "y"}, time_ns=10)
            assert counter.calls == 0
        assert counter.calls == 1
        with log.batch():
            pass
        assert counter.calls == 1  # nothing to sync
    assert len(list(read_log(tmp_path, store=STORE))) == 11


def test_batch_is_not_a_transaction(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with open_log(tmp_path) as log:
        counter = FsyncCounter(monkeypatch)
        with pytest.raises(InvalidEventError), log.batch():
            log.append("search_failed", {"reason": "kept"}, time_ns=0)
            log.append("search_failed", {}, time_ns=1)
        assert counter.calls == 1
        assert log.last_seq == 1
    assert [e.payload["reason"] for e in read_log(tmp_path, store=STORE)] == ["kept"]


def test_failed_write_is_undone(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    write_events(tmp_path, 1)
    before = (tmp_path / "events.log").read_bytes()
    with open_log(tmp_path) as log:
        real_write = os.write

        def half_then_fail(fd: int, data: Any) -> int:
            monkeypatch.setattr(os, "write", real_write)
            real_write(fd, bytes(data)[: len(data) // 2])
            raise OSError(28, "No space left on device")

        monkeypatch.setattr(os, "write", half_then_fail)
        with pytest.raises(OSError, match="No space left"):
            log.append("search_failed", {"reason": "lost"}, time_ns=1)
        assert (tmp_path / "events.log").read_bytes() == before
        assert log.last_seq == 1
        assert log.append("search_failed", {"reason": "ok"}, time_ns=2).seq == 2
    assert [e.seq for e in read_log(tmp_path, store=STORE)] == [1, 2]


def test_a_short_write_writes_the_rest(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A record is written with one ``os.write``; if the kernel takes only part of it (a signal,
    a full pipe of a FUSE mount), the rest follows, and the log reads back whole."""
    write_events(tmp_path, 1)
    real_write = os.write
    calls: list[int] = []

    def short_once(fd: int, data: Any) -> int:
        calls.append(len(data))
        if len(calls) == 1:
            return real_write(fd, bytes(data)[:10])
        return real_write(fd, data)

    with open_log(tmp_path) as log:
        monkeypatch.setattr(os, "write", short_once)
        log.append("search_failed", {"reason": "in two writes"}, time_ns=1)
        monkeypatch.setattr(os, "write", real_write)
        log.append("search_failed", {"reason": "in one"}, time_ns=2)
    assert len(calls) == 2 and calls[1] == calls[0] - 10
    reasons = [e.payload["reason"] for e in read_log(tmp_path, store=STORE)]
    assert reasons[1:] == ["in two writes", "in one"]


def test_failed_fsync_stops_the_writer(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    log = open_log(tmp_path)

    def broken_fsync(fd: int) -> None:
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(os, "fsync", broken_fsync)
    with pytest.raises(OSError, match="Input/output error"):
        log.append("search_failed", {"reason": "x"}, time_ns=0)
    with pytest.raises(LogClosedError, match=r"refuses appends after a failed write.*reopen"):
        log.append("search_failed", {"reason": "y"}, time_ns=1)
    log.close()
    monkeypatch.undo()
    with open_log(tmp_path) as log:
        assert log.last_seq == 1  # what reached the file is still judged by its checksum


def test_closed_log_refuses_appends(tmp_path: Path) -> None:
    log = open_log(tmp_path)
    log.close()
    log.close()
    assert log.closed
    with pytest.raises(LogClosedError, match="is closed"):
        log.append("search_failed", {"reason": "x"}, time_ns=0)


def _sealed_log(directory: Path, n: int) -> bytes:
    with EventLog.open(directory, STREAM, store=STORE) as log:
        for i in range(n):
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=i)
    return (directory / "events.log").read_bytes()


def test_a_sealed_restart_checks_every_acknowledged_byte_before_it_appends(
    tmp_path: Path,
) -> None:
    data = bytearray(_sealed_log(tmp_path, 40))
    durable = json.loads((tmp_path / "durable.json").read_bytes())
    meta = json.loads((tmp_path / "meta.json").read_bytes())
    genesis = zlib.crc32(f"{meta['format']}\n{meta['stream']}\n{meta['run_id']}\n".encode())
    assert durable["seals"] == [[0, len(data), f"{zlib.crc32(data, genesis):08x}"]]
    with EventLog.open(
        tmp_path, STREAM, verify="sealed", store=STORE
    ) as log:  # clean: appends as usual
        log.append("search_failed", {"reason": "after"}, time_ns=99)
    data = bytearray((tmp_path / "events.log").read_bytes())
    data[len(data) // 5] ^= 0x10  # one flipped bit far before the high-water mark
    (tmp_path / "events.log").write_bytes(bytes(data))
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    log = EventLog.open(tmp_path, STREAM, verify="sealed", store=STORE)
    with pytest.raises(CorruptLogError, match="is damaged: one bit of it was flipped"):
        log.append("search_failed", {"reason": "on top of damage"}, time_ns=100)
    with pytest.raises(CorruptLogError):  # every later call too
        log.append("search_failed", {"reason": "again"}, time_ns=100)
    log.close()
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()} == before
    with pytest.raises(CorruptLogError):  # a writer that appends nothing still hears of it
        EventLog.open(tmp_path, STREAM, verify="sealed", store=STORE).close()


def test_seals_that_do_not_match_intact_records_mean_durable_json_is_damaged(
    tmp_path: Path,
) -> None:
    _sealed_log(tmp_path, 5)
    doc = json.loads((tmp_path / "durable.json").read_bytes())
    doc["seals"][0][2] = "00000000"
    (tmp_path / "durable.json").write_text(json.dumps(doc))
    for verify in ("all", "sealed"):
        with (
            pytest.raises(CorruptLogError, match=r"durable\.json is damaged"),
            EventLog.open(tmp_path, STREAM, verify=verify, store=STORE) as log,
        ):
            log.append("search_failed", {"reason": "x"}, time_ns=9)
