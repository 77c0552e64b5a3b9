"""Kill tests of the lake's commits: ``lake add`` and ``lake add --replace`` are killed right
after each of their durable steps (every fsync and rename), then run again; the re-run must
complete and leave the lake exactly as an uninterrupted run does, and at every kill a complete
old or new run must be in the lake (after the recovery any reader or writer does)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import EventLog
from objsearch.events.lake import STAGING, Lake
from objsearch.testing.killtest import KillServer, tree

from .lake_logs import two_type_log

#: Each test runs a command or a fuzzer thousands of times: tens of seconds.
pytestmark = pytest.mark.slow


def _add(log: Path, lake: Path, *extra: str) -> list[str]:
    return ["lake", "add", str(log), "--robot", "r", "--lake", str(lake), *extra]


def _sweep(
    server: KillServer,
    argv: list[str],
    start: Path | None,
    lake: Path,
    reference: dict[str, bytes | None],
) -> list[int]:
    """Kill ``argv`` after step 1, 2, … until it completes; returns the steps killed at."""
    killed: list[int] = []
    n = 0
    while True:
        n += 1
        shutil.rmtree(lake, ignore_errors=True)
        if start is not None:
            shutil.copytree(start, lake)
        outcome = server.run(argv, kill_after=n)
        if not outcome.killed:
            assert outcome.code == 0, outcome.output
            assert tree(lake) == reference
            return killed
        killed.append(n)
        again = server.run(argv)
        assert again.code == 0, f"re-run after a kill at step {n}: {again.output}"
        assert "Traceback" not in again.output
        assert tree(lake) == reference, f"kill at step {n}: the re-run left another lake"
        assert n < 200, "the command never completed"


def test_lake_add_killed_at_every_step_then_rerun_equals_an_uninterrupted_add(
    tmp_path: Path,
) -> None:
    log = two_type_log(tmp_path / "log")
    lake = tmp_path / "lake"
    with KillServer(tmp_path) as server:
        assert server.run(_add(log, lake)).code == 0
        reference = tree(lake)
        assert not list((lake / STAGING).iterdir())
        killed = _sweep(server, _add(log, lake), None, lake, reference)
    # Every staged file's fsync, the manifest's rename, the run's rename, the folders' fsyncs.
    assert len(killed) >= 15


def test_replace_killed_at_every_step_leaves_a_whole_run_and_the_rerun_finishes(
    tmp_path: Path,
) -> None:
    log = two_type_log(tmp_path / "log")
    start = tmp_path / "start"
    lake = tmp_path / "lake"
    with KillServer(tmp_path) as server:
        assert server.run(_add(log, start)).code == 0
        old = Lake(start, store=STORE).runs()[0].digest
        with EventLog.open(log, "run-a", store=STORE) as writer:
            writer.append("search_failed", {"reason": "later"}, time_ns=1000)
        shutil.copytree(start, lake)
        assert server.run(_add(log, lake, "--replace")).code == 0
        [new_run] = Lake(lake, store=STORE).runs()
        reference = tree(lake)
        seen: dict[str, list[int]] = {"old": [], "new": [], "gap": []}
        n = 0
        while True:
            n += 1
            shutil.rmtree(lake)
            shutil.copytree(start, lake)
            outcome = server.run(_add(log, lake, "--replace"), kill_after=n)
            if not outcome.killed:
                assert outcome.code == 0, outcome.output
                break
            staging = (
                sorted(p.name for p in (lake / STAGING).iterdir())
                if (lake / STAGING).is_dir()
                else []
            )
            if not (lake / "robot=r").exists() or not Lake(lake, store=STORE).runs():
                seen["gap"].append(n)  # the moment the issue found: neither run in place
            assert Lake(lake, store=STORE).recover()
            runs = Lake(lake, store=STORE).runs()
            assert len(runs) == 1, f"kill at step {n} ({staging}): runs {runs}"
            assert runs[0].digest in (old, new_run.digest)
            assert Lake(lake, store=STORE).read_events(runs[0])  # whole: every file reads
            seen["old" if runs[0].digest == old else "new"].append(n)
            assert not list((lake / STAGING).iterdir())
            again = server.run(_add(log, lake, "--replace"))
            assert again.code == 0, again.output
            assert tree(lake) == reference, f"kill at step {n}"
    # Killed before the intent record is durable, the old run stays; after it, the new one wins.
    assert seen["old"] and seen["new"] and seen["gap"]
    assert max(seen["old"]) < min(seen["new"])

    # The same window through a real interpreter start: `objsearch lake add` killed with
    # neither run in place, then any reader (here `lake ls`) finishes the replace.
    shutil.rmtree(lake)
    shutil.copytree(start, lake)
    cli = [sys.executable, "-m", "objsearch.cli"]
    killer = [sys.executable, "-m", "objsearch.testing.killtest", str(seen["gap"][0])]
    killed = subprocess.run([*killer, *_add(log, lake, "--replace")], check=False)
    assert killed.returncode == -9
    listing = subprocess.run(
        [
            *cli,
            "query",
            "--lake",
            str(lake),
            "--format",
            "csv",
            "SELECT count(*) FROM search_failed",
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert listing.returncode == 0, listing.stderr
    assert listing.stdout.splitlines()[1] == str(new_run.rows["search_failed"])
    assert "finishing a replace" in listing.stderr


def test_stale_staging_from_a_dead_writer_is_removed_by_the_next(tmp_path: Path) -> None:
    log = two_type_log(tmp_path / "log")
    lake = tmp_path / "lake"
    stale = lake / STAGING / "0123abcd"
    stale.mkdir(parents=True)
    (stale / "moved.parquet").write_bytes(b"PAR1 half")
    (lake / STAGING / "old-0123abcd").mkdir()
    with KillServer(tmp_path) as server:
        outcome = server.run(_add(log, lake))
    assert outcome.code == 0, outcome.output
    assert "removed 2 unfinished commit(s)" in outcome.output
    assert not list((lake / STAGING).iterdir())
    assert len(Lake(lake, store=STORE).runs()) == 1
