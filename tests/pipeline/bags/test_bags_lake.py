"""Ingest's commit: killed right after each durable step (fsync, rename), a re-run completes and
leaves the lake, ingest report included, exactly as an uninterrupted ingest does. Into the fleet
lake (a Delta table; its steps are the data files and the commit) the same, compared as tables:
at every kill the bag's run is not there or is whole."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events.lake import STAGING
from objsearch.events.lake_table import TableLake
from objsearch.pipeline.bags.formats import BagFormat
from objsearch.pipeline.bags.ingest import ingest
from objsearch.pipeline.bags.lake import MANIFESTS, RUN_REPORT, BagLake
from objsearch.pipeline.bags.record import record
from objsearch.testing.killtest import KillServer, table_content, tree

from .splitter import split_ros1


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One short search (each kill re-reads it): every step kind of a bag's commit."""
    path = tmp_path_factory.mktemp("bag") / "run.bag"
    record(path, BagFormat.ROS1, scenes=[1], targets=["Apple"], starts=["kitchen-1"], odom_hz=1.0)
    return path


def test_ingest_killed_at_every_step_then_rerun_equals_an_uninterrupted_ingest(
    bag: Path, tmp_path: Path
) -> None:
    lake = tmp_path / "lake"
    argv = ["ingest", str(bag), "--lake", str(lake), "--no-progress"]
    with KillServer(tmp_path) as server:
        first = server.run(argv)
        assert first.code == 0, first.output
        reference = tree(lake)
        [report] = (lake / MANIFESTS).iterdir()
        [run] = BagLake(lake).lake.runs()
        doc = json.loads(report.read_bytes())
        assert json.loads((run.path / RUN_REPORT).read_bytes())["pieces"][doc["bag_id"]] == doc
        assert doc["run"] == run.run
        reruns = {"committed": 0, "already": 0}
        n = 0
        while True:
            n += 1
            shutil.rmtree(lake, ignore_errors=True)
            outcome = server.run(argv, kill_after=n)
            if not outcome.killed:
                assert outcome.code == 0, outcome.output
                assert tree(lake) == reference
                break
            again = server.run(argv)
            assert again.code == 0, f"re-run after a kill at step {n}: {again.output}"
            reruns["already" if "already in the lake" in again.output else "committed"] += 1
            assert tree(lake) == reference, f"kill at step {n}: the re-run left another lake"
            assert not list((lake / STAGING).iterdir())
            assert n < 200
    # Some kills came after the run's rename (the re-run finds the bag and writes its report).
    assert reruns["already"] >= 1 and reruns["committed"] >= 10, reruns


def test_a_missing_report_is_restored_from_the_run(bag: Path, tmp_path: Path) -> None:
    lake = tmp_path / "lake"
    [done] = ingest([bag], lake)
    assert done.error is None and done.committed > 0
    [report] = (lake / MANIFESTS).iterdir()
    kept = report.read_bytes()
    report.unlink()
    [again] = ingest([bag], lake)
    assert again.already and again.error is None
    assert report.read_bytes() == kept


def test_a_session_merge_killed_at_every_step_then_rerun_equals_an_uninterrupted_one(
    bag: Path, tmp_path: Path
) -> None:
    """Pieces without run_started make a provisional run; the piece holding it then merges
    that run into the session's run and removes it. Killed between any two steps (the new run
    committed, the old one not yet removed; the reports not yet rewritten), the re-run must
    finish the merge: every event id once, the lake as an uninterrupted ingest leaves it."""
    pieces = split_ros1(bag, tmp_path / "split", duration_s=2.0)
    assert len(pieces) == 3
    template = tmp_path / "template"
    ingest(pieces[1:], template)
    [provisional] = BagLake(template).lake.runs()
    assert not provisional.identity.get("run_id")
    lake = tmp_path / "lake"
    argv = ["ingest", str(pieces[0]), "--lake", str(lake), "--no-progress"]
    with KillServer(tmp_path) as server:
        shutil.copytree(template, lake)
        assert server.run(argv).code == 0
        reference = tree(lake)
        [run] = BagLake(lake).lake.runs()
        assert run.identity.get("run_id") and run.run != provisional.run
        n = 0
        while True:
            n += 1
            shutil.rmtree(lake)
            shutil.copytree(template, lake)
            outcome = server.run(argv, kill_after=n)
            if not outcome.killed:
                assert outcome.code == 0, outcome.output
                assert tree(lake) == reference
                break
            again = server.run(argv)
            assert again.code == 0, f"re-run after a kill at step {n}: {again.output}"
            assert tree(lake) == reference, f"kill at step {n}: the re-run left another lake"
            assert n < 200
    assert n > 5  # the merge has steps: the run's commit, the old run's removal, the reports


def test_ingest_into_the_fleet_lake_killed_at_every_step_leaves_the_bag_out_or_whole(
    bag: Path, tmp_path: Path
) -> None:
    empty = tmp_path / "empty"
    TableLake(empty, store=STORE).create()
    argv = ["ingest", str(bag), "--no-progress", "--lake"]
    with KillServer(tmp_path) as server:
        whole = tmp_path / "whole"
        shutil.copytree(empty, whole)
        first = server.run([*argv, str(whole)])
        assert first.code == 0, first.output
        reference = table_content(whole)
        [run] = reference[0]
        nothing = table_content(empty)

        def rerun(lake: Path, n: int, there: bool) -> None:
            again = server.run([*argv, str(lake)])
            assert again.code == 0, f"re-run after a kill at step {n}: {again.output}"
            assert ("already in the lake" in again.output) == there, again.output
            assert table_content(lake) == reference, f"kill at step {n}: the re-run differs"

        seen: dict[str, list[int]] = {"without": [], "whole": []}
        # As in tests/events/test_lake_table_kill.py: every kill before the commit leaves the
        # same lake but for unnamed files; the re-run is tried from the first and the last.
        pending: tuple[Path, int] | None = None
        n = 0
        while True:
            n += 1
            lake = tmp_path / f"k{n}"
            shutil.copytree(empty, lake)
            outcome = server.run([*argv, str(lake)], kill_after=n)
            if not outcome.killed:
                assert outcome.code == 0, outcome.output
                assert table_content(lake) == reference
                break
            now = table_content(lake)
            assert now in (nothing, reference), f"kill at step {n}: part of the bag is there"
            if run not in now[0]:
                seen["without"].append(n)
                if n == 1:
                    rerun(lake, n, there=False)
                else:
                    pending = (lake, n)
                continue
            seen["whole"].append(n)
            if pending is not None:
                rerun(*pending, there=False)
                pending = None
            rerun(lake, n, there=True)
            assert n < 200
    # Every data file is a step (the bag's tables, the derived ones, the run's row), then the
    # commit: killed before it the bag is not there, after it whole.
    assert pending is None and len(seen["without"]) >= 5 and seen["whole"], seen
    assert max(seen["without"]) < min(seen["whole"])
