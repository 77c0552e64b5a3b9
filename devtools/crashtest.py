"""Crash-test harness: kill a writer with SIGKILL at random moments and check what survives.

A *fork server* (one Python process that has already imported the store) forks a fresh writer for
each round, so a round costs a fork, not an interpreter start-up, and hundreds of kills fit in a
test. Each writer opens the log (recovering whatever the previous one left), then appends events of
random sizes, per event or in batches of random length, and reports each acknowledgement (append,
or the batch, returned) on a pipe with one ``write`` per line. The harness kills it after a random
delay (sometimes before it has even finished opening, i.e. during recovery), waits for the server
to confirm the death, and checks, in this process:

* reopening succeeds (a torn tail is cut, with its warning), and finds no mid-file damage;
* every acknowledged event is on disk, byte for byte the event that was acknowledged;
* nothing partial: after the reopen, a read sees no torn tail and only whole, checksum-valid
  records; every event on disk is one some writer really appended;
* seqs are 1, 2, …, n without a gap;
* a new append works and reads back.

SIGKILL leaves the page cache alone, so this tests the order of operations and recovery, not
power loss. Used by ``tests/events/test_crash.py`` (≥ 200 kills) and ``benchmarks/events.py``.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Final

from objsearch.agent.catalogue import STORE
from objsearch.events.errors import EventStoreError, TornTailWarning
from objsearch.events.log import EventLog
from objsearch.events.log_files import LOG_FILE
from objsearch.events.log_read import read_log

STREAM: Final = "crash"

_SERVER: Final = r"""
import os, random, sys, warnings
from objsearch.agent.catalogue import STORE
from objsearch.events import EventLog

warnings.simplefilter("ignore")
STORE.upcaster  # compiled once here, not in every forked writer
for command in sys.stdin:
    directory, seed = command.split()
    pid = os.fork()
    if pid == 0:
        rng = random.Random(int(seed))
        try:
            log = EventLog.open(directory, "crash", store=STORE)
            os.write(1, b"ready\n")
            n = 0
            while True:
                size = rng.choice((8, 8, 8, 200, 3000, 150000, 3000000))
                batch = rng.choice((0, 0, 1, 5, 20))
                acked = []
                def one():
                    global n
                    n += 1
                    tag = f"{seed}.{n}"
                    e = log.append("search_failed", {"reason": tag + ":" + "x" * size}, time_ns=log.last_time_ns + 1)
                    acked.append(f"{e.seq} {e.event_id} {tag} {size}\n")
                if batch:
                    with log.batch():
                        for _ in range(batch):
                            one()
                else:
                    one()
                os.write(1, "".join(acked).encode())
        except BaseException as exc:
            os.write(1, f"error {exc!r}\n".encode())
            os._exit(1)
    sys.stdout.write(f"child {pid}\n")
    sys.stdout.flush()
    _, status = os.waitpid(pid, 0)
    sys.stdout.write(f"dead {status}\n")
    sys.stdout.flush()
"""


class CrashTestFailure(AssertionError):
    """The store broke a promise after a kill."""


@dataclass
class CrashReport:
    kills: int = 0
    killed_while_opening: int = 0
    killed_in_write: int = 0  # kills aimed at a moment when half a record was on disk
    acknowledged: int = 0
    torn_tails_cut: int = 0
    largest_log: int = 0  # events in the longest log at a check
    logs: int = 0
    seconds: float = 0.0


def run_crash_test(
    directory: Path,
    *,
    kills: int,
    seed: int = 0,
    max_delay_s: float = 0.012,
    kills_per_log: int = 25,
    progress: Callable[[CrashReport], None] | None = None,
) -> CrashReport:
    """Kill ``kills`` writers at random moments; raise :class:`CrashTestFailure` on a broken promise.

    A fresh log directory is started every ``kills_per_log`` kills, which keeps the re-reads
    cheap while still piling many crashes onto each log.
    """
    rng = random.Random(seed)
    report = CrashReport()
    started = time.perf_counter()
    server = subprocess.Popen(
        [sys.executable, "-c", _SERVER],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        bufsize=1,
    )
    assert server.stdin is not None and server.stdout is not None
    try:
        acked: dict[int, tuple[str, str, int]] = {}
        log_dir = directory
        for kill in range(kills):
            if kill % kills_per_log == 0:
                log_dir = directory / f"log-{kill // kills_per_log:04d}"
                acked = {}
                report.logs += 1
            _one_round(server.stdin, server.stdout, log_dir, rng, acked, report, seed, kill)
            _check(log_dir, acked, report, kill)
            report.kills += 1
            if progress is not None:
                progress(report)
    finally:
        server.stdin.close()
        server.wait(timeout=10)
    report.seconds = time.perf_counter() - started
    return report


def _one_round(
    stdin: IO[str],
    stdout: IO[str],
    log_dir: Path,
    rng: random.Random,
    acked: dict[int, tuple[str, str, int]],
    report: CrashReport,
    seed: int,
    kill: int,
) -> None:
    stdin.write(f"{log_dir} {seed * 1_000_000 + kill}\n")
    stdin.flush()
    # The server names the child right after the fork; the child may say "ready" first.
    child = 0
    ready = False
    while not child:
        line = stdout.readline()
        if line.startswith("child "):
            child = int(line.split()[1])
        elif line == "ready\n":
            ready = True
        else:
            raise CrashTestFailure(f"round {kill}: unexpected {line!r} from the fork server")
    if not ready and rng.random() < 0.1:
        report.killed_while_opening += 1  # kill as soon as it exists: during open/recovery
    else:
        if not ready and (line := stdout.readline()) != "ready\n":
            raise CrashTestFailure(f"round {kill}: writer did not open the log: {line!r}")
        if rng.random() < 0.3:
            report.killed_in_write += _wait_until_writing(log_dir / LOG_FILE, timeout=0.05)
        else:
            time.sleep(rng.uniform(0, _max_delay(rng)))
    os.kill(child, signal.SIGKILL)
    while True:
        line = stdout.readline()
        if not line:
            raise CrashTestFailure(f"round {kill}: the fork server died")
        if line.startswith("dead "):
            status = int(line.split()[1])
            if not (os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL):
                raise CrashTestFailure(f"round {kill}: writer ended by itself (status {status})")
            return
        if line == "ready\n":
            continue
        if line.startswith("error "):
            raise CrashTestFailure(f"round {kill}: writer failed: {line.strip()}")
        seq, event_id, tag, size = line.split()
        acked[int(seq)] = (event_id, tag, int(size))
        report.acknowledged += 1


def _wait_until_writing(log_file: Path, *, timeout: float) -> bool:
    """Poll until the log's last byte is not a newline, i.e. a record is being written.

    The kernel grows a file page by page during a large ``write``, so a kill right after this
    sees half a record on disk: without it a kill almost never lands inside a write and the
    torn-tail recovery would go unexercised. Returns whether it saw one before ``timeout``.
    """
    deadline = time.monotonic() + timeout
    try:
        fd = os.open(log_file, os.O_RDONLY)
    except OSError:
        time.sleep(timeout)
        return False
    try:
        while time.monotonic() < deadline:
            size = os.fstat(fd).st_size
            if size and os.pread(fd, 1, size - 1) not in (b"\n", b""):
                return True
    finally:
        os.close(fd)
    return False


def _max_delay(rng: random.Random) -> float:
    return rng.choice((0.002, 0.01, 0.03))


def _check(
    log_dir: Path, acked: dict[int, tuple[str, str, int]], report: CrashReport, kill: int
) -> None:
    where = f"after kill {kill} ({log_dir})"
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            log = EventLog.open(log_dir, STREAM, store=STORE)
        if log.torn_tail is not None:
            report.torn_tails_cut += 1
            if not any(issubclass(w.category, TornTailWarning) for w in caught):
                log.close()
                raise CrashTestFailure(f"{where}: a torn tail was cut without a warning")
        with log:
            with warnings.catch_warnings(record=True) as after:
                warnings.simplefilter("always")
                events = list(read_log(log_dir, store=STORE))
            if after:
                raise CrashTestFailure(f"{where}: a torn tail survived the reopen: {after[0]}")
            seqs = [e.seq for e in events]
            if seqs != list(range(1, len(events) + 1)) or log.last_seq != len(events):
                raise CrashTestFailure(f"{where}: seqs are not 1..{len(events)}")
            by_seq = {e.seq: e for e in events}
            for seq, (event_id, tag, size) in acked.items():
                event = by_seq.get(seq)
                if event is None:
                    raise CrashTestFailure(f"{where}: acknowledged seq {seq} is missing")
                if (event.event_id, event.payload["reason"]) != (event_id, f"{tag}:{'x' * size}"):
                    raise CrashTestFailure(f"{where}: seq {seq} is not what was acknowledged")
            for event in events:
                tag, _, fill = str(event.payload["reason"]).partition(":")
                if event.type != "search_failed" or set(fill) - {"x"} or "." not in tag:
                    raise CrashTestFailure(f"{where}: seq {event.seq} was never appended")
            probe = log.append("search_failed", {"reason": "probe.0:"}, time_ns=log.last_time_ns)
        last = list(read_log(log_dir, from_seq=probe.seq, store=STORE))
        if last != [probe]:
            raise CrashTestFailure(f"{where}: the append after recovery did not read back")
        # The probe is a real event now; later rounds must find it too.
        acked[probe.seq] = (probe.event_id, "probe.0", 0)
        report.largest_log = max(report.largest_log, probe.seq)
    except EventStoreError as exc:
        raise CrashTestFailure(f"{where}: {type(exc).__name__}: {exc}") from exc
