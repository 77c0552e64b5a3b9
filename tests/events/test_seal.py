"""The writer's seals: records added together (:meth:`Sealer.add_all`, what the log does at each
fsync) give the seals that adding them one by one gives, also where a range closes among them."""

from __future__ import annotations

import json
import zlib
from pathlib import Path

import pytest

import objsearch.events.seal as seal
from objsearch.agent.catalogue import STORE
from objsearch.events import EventLog
from objsearch.events.seal import Sealer, seals_from_json


def _records(n: int) -> list[bytes]:
    return [b'{"n":%d,"pad":"%s"}\t00000000\n' % (i, b"x" * (i % 37)) for i in range(n)]


@pytest.mark.parametrize("seal_bytes", [64, 500, 1 << 20])
@pytest.mark.parametrize("chunk", [1, 3, 50, 400])
def test_records_added_together_are_sealed_as_one_by_one(
    seal_bytes: int, chunk: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(seal, "SEAL_BYTES", seal_bytes)
    records = _records(400)
    one_by_one, together = Sealer(crc=12345), Sealer(crc=12345)
    for data in records:
        one_by_one.add(data)
    for start in range(0, len(records), chunk):
        together.add_all(records[start : start + chunk])
    assert together.seals() == one_by_one.seals()
    assert together.closed_count == one_by_one.closed_count
    assert (seal_bytes >= 1 << 20) == (together.closed_count == 0)


def test_a_logs_seals_are_the_seals_of_its_records_one_by_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The log adds what it wrote to its seals at each fsync and every 256 records: its
    durable.json holds the seals of its records one by one, ranges closing every ~2 kB."""
    monkeypatch.setattr(seal, "SEAL_BYTES", 2048)
    with EventLog.open(tmp_path, "s", store=STORE) as log:
        for start in range(0, 1200, 400):
            with log.batch():
                for i in range(start, start + 400):
                    log.append("search_failed", {"reason": f"r{i}"}, time_ns=i)
        log.append("search_failed", {"reason": "alone"}, time_ns=5000)
    meta = json.loads((tmp_path / "meta.json").read_bytes())
    genesis = zlib.crc32(f"{meta['format']}\n{meta['stream']}\n{meta['run_id']}\n".encode())
    expected = Sealer(crc=genesis)
    for line in (tmp_path / "events.log").read_bytes().splitlines(keepends=True):
        expected.add(line)
    durable = json.loads((tmp_path / "durable.json").read_bytes())
    assert seals_from_json(durable["seals"]) == expected.seals()
    assert expected.closed_count > 10
    with EventLog.open(tmp_path, "s", store=STORE, verify="sealed") as log:  # they check
        log.append("search_failed", {"reason": "after"}, time_ns=6000)
