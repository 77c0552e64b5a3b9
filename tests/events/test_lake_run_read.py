"""A fleet-lake run read a slice at a time (``events/lake/run_read.py``) as ``replay`` and
``where`` read it: each type's events merged in seq order, the row filter left out only where
the files' statistics say they hold the run's rows alone, and the collector kept from running
inside a slice's making."""

from __future__ import annotations

import gc
import heapq
import random
from pathlib import Path

from objsearch.agent.catalogue import STORE
from objsearch.events import Event, EventLog, read_log
from objsearch.events.lake import TableLake, add_log
from objsearch.events.lake.run_read import EVENT_ROWS, RunReader, _merge_by_seq, _only_rows_of

from .lake_logs import small_log
from .payloads import EXAMPLES, OLD_EXAMPLES


def _event(seq: int) -> Event:
    return Event(
        event_id=f"00000000-0000-4000-8000-{seq:012x}",
        stream="s",
        seq=seq,
        time_ns=seq,
        recorded_at_ns=seq,
        type="search_failed",
        version=1,
        task_id=None,
        payload={"reason": "r"},
    )


def test_the_merge_orders_every_event_by_seq_as_heapq_merge_does() -> None:
    rng = random.Random(7)
    for _ in range(200):
        seqs = rng.sample(range(1, 400), rng.randint(0, 300))
        owners: list[list[int]] = [[] for _ in range(rng.randint(1, 6))]
        for seq in sorted(seqs):
            rng.choice(owners).append(seq)
        sources: list[list[list[Event]]] = []
        for owned in owners:
            chunks, at = [], 0
            while at < len(owned):  # chunks of any length, empty ones among them
                size = rng.randint(0, 40)
                chunks.append([_event(s) for s in owned[at : at + size]])
                at += size
            sources.append(chunks)
        merged = [e.seq for out in _merge_by_seq([iter(c) for c in sources]) for e in out]
        expected = [
            e.seq
            for e in heapq.merge(*([e for c in s for e in c] for s in sources), key=lambda e: e.seq)
        ]
        assert merged == expected == sorted(seqs)


def _long_log(directory: Path, n: int) -> Path:
    """An old detection version, then ``n`` detections and ``n`` failures interleaved: each
    type's rows span several slices."""
    with EventLog.open(
        directory, "run-a", wall_clock=lambda: 1_700_000_000_000_000_000, store=STORE
    ) as log:
        log.append("detection", OLD_EXAMPLES["detection", 1], time_ns=0, version=1)
        for i in range(n):
            log.append("detection", EXAMPLES["detection"], time_ns=1 + 2 * i, task_id="t1")
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=2 + 2 * i)
    return directory


def test_a_long_run_streams_as_its_log_with_one_collection_a_slice(tmp_path: Path) -> None:
    """Making a slice's events (~6 containers a row) ran the young collection ~8 times a slice
    (the 4 slices here: 23 collections); now it runs after each slice at most."""
    log = _long_log(tmp_path / "log", n=3 * EVENT_ROWS // 2)
    lake = TableLake(tmp_path / "lake", store=STORE)
    add_log(log, lake, robot="r")
    (run,) = lake.runs()
    reader = RunReader(lake, run)
    reader.check()
    slices = sum(-(-rows // EVENT_ROWS) for rows in run.rows.values())
    was = gc.isenabled()
    gc.enable()
    try:
        gc.collect()
        before = gc.get_stats()[0]["collections"]
        events = list(reader.events())
        collections = gc.get_stats()[0]["collections"] - before
    finally:
        if not was:
            gc.disable()
    assert events == lake.read_events(run) == list(read_log(log, store=STORE))
    assert events[0].version == events[1].version  # the old detection came upcast
    assert collections <= slices + 2, (collections, slices)


def test_the_row_filter_is_left_out_only_for_files_of_the_run_alone(tmp_path: Path) -> None:
    logs = [small_log(tmp_path / f"log{i}", stream=f"s{i}", n=i) for i in range(2)]
    lake = TableLake(tmp_path / "lake", store=STORE)
    for log in logs:
        add_log(log, lake, robot="r")
    runs = lake.runs()

    def files_of_run_alone(run_index: int) -> list[bool]:
        run = runs[run_index]
        holding = lake._files_holding(lake.table(), run.robot, [run.run])
        return [_only_rows_of(lake.files_dataset([f]), run) for f in holding]

    assert all(files_of_run_alone(0)) and all(files_of_run_alone(1))
    stranger = lake.files_dataset([f for f in lake.data_files() if f.kind == "search_failed"][:1])
    assert not all(_only_rows_of(stranger, run) for run in runs)  # one file, two runs' tests
    lake.compact(vacuum_hours=0)  # one file a type, of both runs
    assert not any(files_of_run_alone(0)) and not any(files_of_run_alone(1))
    for run, log in zip(runs, logs, strict=True):
        events = list(RunReader(lake, run).events())
        assert events == lake.read_events(run) == list(read_log(log, store=STORE))
