"""Acknowledged means durable: kill a writer process at a random point, find every ack on disk.

SIGKILL leaves the page cache alone, so this checks the writer's order of operations (write,
fsync, then acknowledge) and recovery on reopen, not power loss; a fuller crash harness that
cuts the file at arbitrary points lives elsewhere.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import EventLog, LogLockedError, TornTailWarning, read_log

WRITER = r"""
import sys
from objsearch.agent.catalogue import STORE
from objsearch.events import EventLog

directory, batch = sys.argv[1], int(sys.argv[2])
with EventLog.open(directory, "crash", store=STORE) as log:
    print("ready", flush=True)
    i = 0
    while True:
        if batch:
            with log.batch():
                events = [
                    log.append("search_failed", {"reason": f"r{i}.{k}"}, time_ns=log.last_time_ns)
                    for k in range(batch)
                ]
        else:
            events = [log.append("search_failed", {"reason": f"r{i}"}, time_ns=log.last_time_ns)]
        for event in events:  # acknowledged: append (or the batch) has returned
            # One write per line: print() may emit its arguments in separate writes, and a kill
            # between them would leave half an ack.
            sys.stdout.write(f"{event.seq} {event.event_id} {event.payload['reason']}\n")
            sys.stdout.flush()
        i += 1
"""


@pytest.mark.parametrize("batch", [0, 7], ids=["per-append", "batched"])
def test_every_acknowledged_event_survives_sigkill(tmp_path: Path, batch: int) -> None:
    acked: dict[int, tuple[str, str]] = {}
    for kill_after in (5, 23, 61):
        proc = subprocess.Popen(
            [sys.executable, "-c", WRITER, str(tmp_path), str(batch)],
            stdout=subprocess.PIPE,
            text=True,
        )
        assert proc.stdout is not None
        try:
            assert proc.stdout.readline() == "ready\n"
            if kill_after == 5:  # once: the lock is held across processes, naming the holder
                with pytest.raises(LogLockedError, match=f"pid {proc.pid}"):
                    EventLog.open(tmp_path, "crash", store=STORE)
            for _ in range(kill_after):
                seq, event_id, reason = proc.stdout.readline().split()
                acked[int(seq)] = (event_id, reason)
        finally:
            os.kill(proc.pid, signal.SIGKILL)
            rest, _ = proc.communicate()
        # Acks printed before the kill landed; a last fragment without "\n" is no ack.
        for line in rest.split("\n")[:-1]:
            seq, event_id, reason = line.split()
            acked[int(seq)] = (event_id, reason)
        assert proc.returncode == -signal.SIGKILL

        with warnings.catch_warnings():
            # A kill inside write() may leave a torn tail; it holds no acknowledged event.
            warnings.simplefilter("ignore", TornTailWarning)
            on_disk = {
                e.seq: (e.event_id, e.payload["reason"]) for e in read_log(tmp_path, store=STORE)
            }
            with EventLog.open(
                tmp_path, "crash", store=STORE
            ) as log:  # the dead writer's lock is gone
                assert log.last_seq >= max(acked)
        assert {seq: on_disk.get(seq) for seq in acked} == acked
