"""The lake's writer lock, with real processes: a second commit waits (bounded, saying so) or
says clearly that another commit holds the lake; never a traceback, never two runs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from objsearch.events.lake import STAGING, Lake

from .test_lake_kill import small_log

CLI = [sys.executable, "-m", "objsearch.cli"]
HOLDER = """
import sys, time
from objsearch.events.lake import Lake
with Lake(sys.argv[1]).locked():
    print("locked", flush=True)
    time.sleep(float(sys.argv[2]))
"""


def _add(log: Path, lake: Path, *extra: str) -> list[str]:
    return [*CLI, "lake", "add", str(log), "--robot", "r", "--lake", str(lake), *extra]


def _holder(lake: Path, seconds: float) -> subprocess.Popen[str]:
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(lake), str(seconds)], stdout=subprocess.PIPE, text=True
    )
    assert holder.stdout is not None and holder.stdout.readline() == "locked\n"
    return holder


def test_two_concurrent_adds_of_one_log_give_one_run_and_no_traceback(tmp_path: Path) -> None:
    log = small_log(tmp_path / "log")
    lake = tmp_path / "lake"
    for _ in range(3):
        procs = [
            subprocess.Popen(
                _add(log, lake), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
            )
            for _ in range(2)
        ]
        results = [(p.wait(timeout=120), *p.communicate()) for p in procs]
        for code, out, err in results:
            assert code == 0, err
            assert "Traceback" not in err and "run=run-a" in out
        assert len(Lake(lake).runs()) == 1
        assert not list((lake / STAGING).iterdir())


def test_a_writer_that_will_not_wait_says_who_holds_the_lake(tmp_path: Path) -> None:
    log = small_log(tmp_path / "log")
    lake = tmp_path / "lake"
    lake.mkdir()
    holder = _holder(lake, 30)
    try:
        busy = subprocess.run(
            _add(log, lake, "--wait", "0"), capture_output=True, text=True, check=False
        )
    finally:
        holder.kill()
        holder.wait()
    assert busy.returncode == 2
    assert busy.stderr.startswith("objsearch: error: ")
    assert f"another commit holds the lake by pid {holder.pid}" in busy.stderr
    assert Lake(lake).runs() == []


def test_a_writer_waits_for_the_lock_then_commits(tmp_path: Path) -> None:
    log = small_log(tmp_path / "log")
    lake = tmp_path / "lake"
    lake.mkdir()
    holder = _holder(lake, 1.5)
    waited = subprocess.run(
        _add(log, lake, "--wait", "60"), capture_output=True, text=True, check=False
    )
    holder.wait()
    assert waited.returncode == 0, waited.stderr
    assert (
        "another commit holds the lake" in waited.stderr and "waiting up to 60 s" in waited.stderr
    )
    assert len(Lake(lake).runs()) == 1


def test_a_holder_killed_mid_commit_releases_the_lake(tmp_path: Path) -> None:
    log = small_log(tmp_path / "log")
    lake = tmp_path / "lake"
    lake.mkdir()
    holder = _holder(lake, 60)
    holder.kill()  # the kernel drops an flock with its holder: no stale lock to clear by hand
    holder.wait()
    done = subprocess.run(
        _add(log, lake, "--wait", "0"), capture_output=True, text=True, check=False
    )
    assert done.returncode == 0, done.stderr
