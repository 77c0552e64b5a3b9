"""The lake's writer lock, with real processes: a second commit waits (bounded, saying so) or
says clearly that another commit holds the lake; never a traceback, never two runs.

No step depends on how fast a process starts: the holder says when it holds the lock and holds it
until told to let go, and the waiting writer is let go only once it has said that it waits."""

from __future__ import annotations

import queue
import subprocess
import sys
import threading
from pathlib import Path
from typing import IO

from objsearch.agent.catalogue import STORE
from objsearch.events.lake import STAGING, Lake

from .lake_logs import two_type_log

CLI = [sys.executable, "-m", "objsearch.cli"]
#: Holds the lake's lock from "locked" on stdout until a line (or the end) on stdin.
HOLDER = """
import sys
from objsearch.events.lake import Lake
with Lake(sys.argv[1]).locked():
    print("locked", flush=True)
    sys.stdin.readline()
"""
#: Seconds to wait for a process to say something or to finish: generous, since a fresh
#: interpreter on a loaded machine takes seconds; the wait ends as soon as it is done.
DEADLINE_S = 120.0


def _add(log: Path, lake: Path, *extra: str) -> list[str]:
    return [*CLI, "lake", "add", str(log), "--robot", "r", "--lake", str(lake), *extra]


def _holder(lake: Path) -> subprocess.Popen[str]:
    """A process holding the lake's lock (it has said so) until :func:`_release`."""
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(lake)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert holder.stdout is not None and holder.stdout.readline() == "locked\n"
    return holder


def _release(holder: subprocess.Popen[str]) -> None:
    assert holder.stdin is not None
    holder.stdin.close()
    assert holder.wait(timeout=DEADLINE_S) == 0


def _lines(stream: IO[str] | None) -> queue.Queue[str]:
    """The lines of ``stream`` as they come, read on a thread ("" at the end)."""
    assert stream is not None
    lines: queue.Queue[str] = queue.Queue()

    def read() -> None:
        for line in stream:
            lines.put(line)
        lines.put("")

    threading.Thread(target=read, daemon=True).start()
    return lines


def test_two_concurrent_adds_of_one_log_give_one_run_and_no_traceback(tmp_path: Path) -> None:
    log = two_type_log(tmp_path / "log")
    lake = tmp_path / "lake"
    for _ in range(3):
        procs = [
            subprocess.Popen(
                _add(log, lake), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
            )
            for _ in range(2)
        ]
        results = [(p.wait(timeout=DEADLINE_S), *p.communicate()) for p in procs]
        for code, out, err in results:
            assert code == 0, err
            assert "Traceback" not in err and "run=run-a" in out
        assert len(Lake(lake, store=STORE).runs()) == 1
        assert not list((lake / STAGING).iterdir())


def test_a_writer_that_will_not_wait_says_who_holds_the_lake(tmp_path: Path) -> None:
    log = two_type_log(tmp_path / "log")
    lake = tmp_path / "lake"
    lake.mkdir()
    holder = _holder(lake)
    try:
        busy = subprocess.run(
            _add(log, lake, "--wait", "0"),
            capture_output=True,
            text=True,
            check=False,
            timeout=DEADLINE_S,
        )
    finally:
        _release(holder)
    assert busy.returncode == 2
    assert busy.stderr.startswith("objsearch: error: ")
    assert f"another commit holds the lake by pid {holder.pid}" in busy.stderr
    assert Lake(lake, store=STORE).runs() == []


def test_a_writer_waits_for_the_lock_then_commits(tmp_path: Path) -> None:
    log = two_type_log(tmp_path / "log")
    lake = tmp_path / "lake"
    lake.mkdir()
    holder = _holder(lake)
    writer = subprocess.Popen(
        _add(log, lake, "--wait", "600"), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    said: list[str] = []
    try:
        lines = _lines(writer.stderr)
        # The writer is let go only once it says it waits: however long it took to start.
        while not said or "another commit holds the lake" not in said[-1]:
            said.append(lines.get(timeout=DEADLINE_S))
            assert said[-1], f"the writer ended without saying that it waits: {said}"
        assert Lake(lake, store=STORE).runs() == []  # it waits, it has not committed
    finally:
        _release(holder)
    assert writer.wait(timeout=DEADLINE_S) == 0, said
    assert "waiting up to 600 s" in said[-1]
    assert len(Lake(lake, store=STORE).runs()) == 1


def test_a_holder_killed_mid_commit_releases_the_lake(tmp_path: Path) -> None:
    log = two_type_log(tmp_path / "log")
    lake = tmp_path / "lake"
    lake.mkdir()
    holder = _holder(lake)
    holder.kill()  # the kernel drops an flock with its holder: no stale lock to clear by hand
    holder.wait()
    done = subprocess.run(
        _add(log, lake, "--wait", "0"),
        capture_output=True,
        text=True,
        check=False,
        timeout=DEADLINE_S,
    )
    assert done.returncode == 0, done.stderr
