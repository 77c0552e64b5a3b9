"""Readers may tail a log while its writer appends (follow_log).

The reader across processes stops at the writer's last event, not after a quiet spell: how fast
a fresh interpreter starts (seconds on a loaded machine) must not decide what it reads."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import CorruptLogError, EventLog, follow_log, read_log

WRITER = r"""
import sys, time
from objsearch.agent.catalogue import STORE
from objsearch.events import EventLog

with EventLog.open(sys.argv[1], "live", store=STORE) as log:
    for i in range(int(sys.argv[2])):
        if i % 10 == 0:
            with log.batch():
                for k in range(5):
                    log.append("search_failed", {"reason": f"b{i}.{k}"}, time_ns=i)
        else:
            log.append("search_failed", {"reason": "x" * (i * 97 % 5000)}, time_ns=i)
        time.sleep(0.001)
"""


#: Events the writer appends for 120 rounds: 12 batches of 5 and 108 single appends.
WRITTEN = 12 * 5 + 108
#: Only a bound for a writer that never finishes; the reader stops at its last event.
DEADLINE_S = 120.0


def test_a_reader_follows_a_writer_in_another_process(tmp_path: Path) -> None:
    with EventLog.open(tmp_path, "live", store=STORE):
        pass  # the log exists before the reader starts
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(tmp_path), "120"])
    seen: list[int] = []
    try:
        for event in follow_log(
            tmp_path, poll_interval=0.005, idle_timeout=DEADLINE_S, store=STORE
        ):
            seen.append(event.seq)
            if event.seq == WRITTEN:
                break
    finally:
        proc.wait(timeout=DEADLINE_S)
    assert proc.returncode == 0
    assert seen == list(range(1, WRITTEN + 1))
    assert len(list(read_log(tmp_path, store=STORE))) == WRITTEN


def test_follow_waits_for_an_unfinished_line_then_reads_it(tmp_path: Path) -> None:
    # The donor is the same run (run id, clock), so its second line chains onto ours.
    run = "00000000-0000-4000-8000-000000000001"
    with EventLog.open(tmp_path, "s", run_id=run, wall_clock=lambda: 0, store=STORE) as log:
        log.append("search_failed", {"reason": "a"}, time_ns=0)
    with EventLog.open(
        tmp_path / "other", "s", run_id=run, wall_clock=lambda: 0, store=STORE
    ) as donor:
        donor.append("search_failed", {"reason": "a"}, time_ns=0)
        donor.append("search_failed", {"reason": "b"}, time_ns=0)
    line2 = (tmp_path / "other" / "events.log").read_bytes().splitlines(keepends=True)[1]
    follower = follow_log(tmp_path, poll_interval=0.001, idle_timeout=0.05, store=STORE)
    assert next(follower).seq == 1
    with (tmp_path / "events.log").open("ab") as f:
        f.write(line2[:20])  # half a record: not yet an event
        f.flush()
        assert [
            e.seq for e in follow_log(tmp_path, from_seq=2, idle_timeout=0.02, store=STORE)
        ] == []
        f.write(line2[20:])
    assert [e.seq for e in follower] == [2]


def test_follow_reports_mid_file_corruption_with_its_position(tmp_path: Path) -> None:
    with EventLog.open(tmp_path, "s", store=STORE) as log:
        for i in range(3):
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=0)
    data = bytearray((tmp_path / "events.log").read_bytes())
    second = data.index(b"\n") + 1
    data[second + 5] ^= 0x01
    (tmp_path / "events.log").write_bytes(bytes(data))
    with pytest.raises(CorruptLogError) as info:
        list(follow_log(tmp_path, idle_timeout=0.01, store=STORE))
    assert (info.value.line, info.value.offset) == (2, second)
