"""Ingest's commit into the fleet lake (a Delta table; its steps are the data files and the
commit), killed right after each durable step: at every kill the bag's run is not there or is
whole — and a session's merge (the new run in, the provisional run out) all or nothing — and a
re-run leaves the lake, compared as tables, as an uninterrupted ingest does."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from devtools.killtest import KillServer, table_content
from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake
from objsearch.pipeline.bags.formats import BagFormat
from objsearch.pipeline.bags.ingest import ingest
from objsearch.pipeline.bags.record import record

from .splitter import split_ros1


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One short search (each kill re-reads it): every step kind of a bag's commit."""
    path = tmp_path_factory.mktemp("bag") / "run.bag"
    record(path, BagFormat.ROS1, scenes=[1], targets=["Apple"], starts=["kitchen-1"], odom_hz=1.0)
    return path


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


def test_a_session_merge_killed_at_every_step_is_all_or_nothing(bag: Path, tmp_path: Path) -> None:
    """Pieces without run_started make a provisional run; the piece holding it then merges that
    run into the session's run and takes it out, in the same transaction: killed at any step,
    the lake holds the provisional run or the merged one, never both or neither, and the re-run
    leaves it as an uninterrupted ingest does."""
    pieces = split_ros1(bag, tmp_path / "split", duration_s=2.0)
    assert len(pieces) == 3
    template = tmp_path / "template"
    ingest(pieces[1:], template)
    [provisional] = TableLake(template, store=STORE).runs()
    assert not provisional.identity.get("run_id")
    before = table_content(template)
    argv = ["ingest", str(pieces[0]), "--no-progress", "--lake"]
    with KillServer(tmp_path) as server:
        whole = tmp_path / "whole"
        shutil.copytree(template, whole)
        assert server.run([*argv, str(whole)]).code == 0
        reference = table_content(whole)
        [run] = TableLake(whole, store=STORE).runs()
        assert run.identity.get("run_id") and run.run != provisional.run
        assert reference != before
        outcomes: list[bool] = []  # per kill: was the merge in?
        n = 0
        while True:
            n += 1
            lake = tmp_path / f"k{n}"
            shutil.copytree(template, lake)
            outcome = server.run([*argv, str(lake)], kill_after=n)
            if not outcome.killed:
                assert outcome.code == 0, outcome.output
                assert table_content(lake) == reference
                break
            now = table_content(lake)
            assert now in (before, reference), f"kill at step {n}: half a merge"
            merged = now == reference
            # the re-run from the first kill and from the first kill after the commit
            if n == 1 or (merged and True not in outcomes):
                again = server.run([*argv, str(lake)])
                assert again.code == 0, f"re-run after a kill at step {n}: {again.output}"
                assert table_content(lake) == reference, f"kill at step {n}: the re-run differs"
            outcomes.append(merged)
            shutil.rmtree(lake)
            assert n < 200
    # Every data file the merge writes is a step (content-addressed files of our own, the
    # provisional run's files rewritten without it; each stored once since a7a8ab1): measured
    # 2026-12-06, 19 kills before the commit left the provisional run, the 20th, right after
    # the commit, the merged one (47 and the 48th before a7a8ab1).
    assert outcomes and outcomes == sorted(outcomes), outcomes
