"""The crash harness: ≥ 200 SIGKILLs at random moments; damage in the middle is located exactly."""

from __future__ import annotations

import random
import warnings
from pathlib import Path

import pytest

from devtools.crashtest import CrashReport, CrashTestFailure, _check, run_crash_test
from objsearch.agent.catalogue import STORE
from objsearch.events import CorruptLogError, EventLog, TornTailWarning, read_log

KILLS = 200


def test_every_acknowledged_event_survives_200_random_sigkills(tmp_path: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TornTailWarning)
        report = run_crash_test(tmp_path, kills=KILLS, seed=4)
    assert report.kills == KILLS
    # The kills really hit the interesting moments, not only the quiet ones.
    assert report.acknowledged > KILLS
    assert report.killed_while_opening > 0
    assert report.torn_tails_cut > 0
    assert report.largest_log > 50


def _log_with(directory: Path, n: int) -> dict[int, tuple[str, str, int]]:
    acked = {}
    with EventLog.open(directory, "crash", store=STORE) as log:
        for i in range(n):
            e = log.append("search_failed", {"reason": f"1.{i}:xx"}, time_ns=i)
            acked[e.seq] = (e.event_id, f"1.{i}", 2)
    return acked


def test_the_harness_notices_a_lost_acknowledged_event(tmp_path: Path) -> None:
    acked = _log_with(tmp_path, 3)
    acked[4] = ("00000000-0000-0000-0000-000000000004", "1.3", 2)
    with pytest.raises(CrashTestFailure, match="acknowledged seq 4 is missing"):
        _check(tmp_path, acked, report=CrashReport(), kill=0)


def test_the_harness_notices_an_event_that_differs_from_its_ack(tmp_path: Path) -> None:
    acked = _log_with(tmp_path, 3)
    acked[2] = (acked[2][0], acked[2][1], 5)
    with pytest.raises(CrashTestFailure, match="seq 2 is not what was acknowledged"):
        _check(tmp_path, acked, report=CrashReport(), kill=0)


@pytest.mark.parametrize("seed", range(40))
def test_damage_in_the_middle_is_reported_at_its_record(tmp_path: Path, seed: int) -> None:
    rng = random.Random(seed)
    with EventLog.open(tmp_path, "s", store=STORE) as log:
        for i in range(rng.randint(3, 12)):
            log.append("search_failed", {"reason": "r" * rng.randint(0, 300)}, time_ns=i)
    path = tmp_path / "events.log"
    data = bytearray(path.read_bytes())
    starts = [0, *[i + 1 for i, b in enumerate(data) if b == ord("\n")][:-1]]
    victim = rng.randrange(len(starts) - 1)  # never the last record: that would be a torn tail
    end = starts[victim + 1]
    pos = rng.randrange(starts[victim], end)
    damage = rng.choice(["flip", "zero", "drop", "newline"])
    if damage == "flip":
        data[pos] ^= 1 << rng.randrange(8)
    elif damage == "zero":
        data[pos] = 0 if data[pos] else 1
    elif damage == "drop":
        del data[pos]
    else:
        data[pos] = ord("\n") if data[pos] != ord("\n") else ord("x")
    path.write_bytes(bytes(data))
    before = path.read_bytes()
    for attempt in (
        lambda: list(read_log(tmp_path, store=STORE)),
        lambda: EventLog.open(tmp_path, "s", store=STORE),
    ):
        with pytest.raises(CorruptLogError) as info:
            attempt()
        assert info.value.offset == starts[victim], damage
        assert info.value.line == victim + 1
        assert f"byte offset {starts[victim]}" in str(info.value)
    assert path.read_bytes() == before  # reported, never "repaired"
