"""One recording session is one run: split bags, any order, other formats, one clock, re-ingest."""

from __future__ import annotations

import datetime as dt
import random
from pathlib import Path

import pyarrow.compute as pc
import pytest

from objsearch.events.lake import Lake, LakeError, compact_log
from objsearch.pipeline.bags.formats import BagFormat
from objsearch.pipeline.bags.ingest import ingest
from objsearch.pipeline.bags.lake import BagLake
from objsearch.ros.topics import TopicMap

from .bag_fixtures import Recorded, record_run
from .splitter import split_ros1

BAG_CLOCK_2026 = int(dt.datetime(2026, 1, 1, tzinfo=dt.UTC).timestamp() * 1e9)


@pytest.fixture(scope="module")
def ros1(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    return record_run(tmp_path_factory.mktemp("sessions"), BagFormat.ROS1)


@pytest.fixture(scope="module")
def pieces(ros1: Recorded, tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    cut = split_ros1(ros1.bag, tmp_path_factory.mktemp("split"), duration_s=60.0)
    assert len(cut) >= 3
    return cut


def _content(lake: Path) -> tuple[list[tuple[str, int, str]], dict[str, int], list[int]]:
    """What a run says, ids of derived events aside: agent events, rows per type, pose times."""
    runs = Lake(lake).runs()
    assert len(runs) == 1, [r.run for r in runs]
    tables = Lake(lake).read_tables(runs[0])
    agent = sorted(
        (e.event_id, e.time_ns, e.type)
        for e in Lake(lake).read_events(runs[0])
        if not e.stream.startswith("bag:")
    )
    rows = {t: table.num_rows for t, table in tables.items()}
    poses = sorted(tables["pose_observed"]["time_ns"].to_pylist())
    return agent, rows, poses


def test_split_pieces_in_any_order_are_one_run(
    ros1: Recorded, pieces: list[Path], tmp_path: Path
) -> None:
    ingest([ros1.bag], tmp_path / "whole")
    shuffled = pieces[:]
    random.Random(3).shuffle(shuffled)
    results = ingest(shuffled, tmp_path / "split")
    assert [r.error for r in results] == [None] * len(pieces)
    assert _content(tmp_path / "split") == _content(tmp_path / "whole")
    [run] = Lake(tmp_path / "split").runs()
    assert run.date == "2026-01-01" and run.identity.get("run_id")
    assert not list((tmp_path / "split").glob("robot=*/date=1970-*"))


def test_pieces_at_different_times_first_one_last(
    ros1: Recorded, pieces: list[Path], tmp_path: Path
) -> None:
    lake = tmp_path / "lake"
    later = [ingest([p], lake) for p in pieces[1:]]  # the first piece (run_started) comes last
    assert all(r.error is None and r.committed > 0 for [r] in later)
    [first] = ingest([pieces[0]], lake)
    assert first.error is None and "merged into run" in first.note
    ingest([ros1.bag], tmp_path / "whole")
    assert _content(lake) == _content(tmp_path / "whole")
    searches = Lake(lake).runs()[0].path / "_derived"
    assert list(searches.glob("searches.*.parquet"))
    assert len(BagLake(lake).known_pieces()) == len(pieces)


def test_the_same_recording_in_three_formats_counts_once(ros1: Recorded, tmp_path: Path) -> None:
    sqlite = record_run(tmp_path / "sqlite", BagFormat.ROS2_SQLITE3)
    mcap = record_run(tmp_path / "mcap", BagFormat.ROS2_MCAP)
    lake = tmp_path / "lake"
    results = ingest([ros1.bag, sqlite.bag, mcap.bag], lake)
    assert results[0].committed > 0
    for r in results[1:]:
        assert r.error is None and r.committed == 0 and "already in the lake" in r.note
    ingest([ros1.bag], tmp_path / "one")
    assert _content(lake) == _content(tmp_path / "one")
    again = ingest([mcap.bag], lake)  # known now: not read again
    assert again[0].already and again[0].report is None


def test_a_piece_with_nothing_in_it_makes_no_run(tmp_path: Path) -> None:
    from rosbags.rosbag1 import Writer

    empty = tmp_path / "empty.bag"
    with Writer(empty) as writer:
        writer.add_connection("/chatter", "std_msgs/msg/String", typestore=None)
    [result] = ingest([empty], tmp_path / "lake")
    assert result.error is None and result.committed == 0 and "nothing committed" in result.note
    assert Lake(tmp_path / "lake").runs() == []


def test_one_clock_per_run(ros1: Recorded, tmp_path: Path) -> None:
    [result] = ingest([ros1.bag], tmp_path / "lake")
    assert result.report is not None and result.report.clock_offset_ns == BAG_CLOCK_2026
    [run] = Lake(tmp_path / "lake").runs()
    tables = Lake(tmp_path / "lake").read_tables(run)
    start, end = result.report.start_ns, result.report.end_ns
    assert start is not None and end is not None
    for event_type, table in tables.items():
        times = table["time_ns"]
        assert pc.min(times).as_py() >= start and pc.max(times).as_py() <= end, event_type
    logged = {e.event_id: e.time_ns for e in ros1.log}
    for e in Lake(tmp_path / "lake").read_events(run):
        if e.event_id in logged:
            assert e.time_ns == logged[e.event_id] + BAG_CLOCK_2026


def test_a_changed_topic_map_reingests(ros1: Recorded, tmp_path: Path) -> None:
    lake = tmp_path / "lake"
    [first] = ingest([ros1.bag], lake)
    no_odom = TopicMap({t: r for t, r in TopicMap().topics.items() if t != "/odom"})
    [again] = ingest([ros1.bag], lake, topic_map=no_odom)
    assert not again.already and again.report is not None
    [run] = Lake(lake).runs()
    assert first.report is not None
    # Poses now come from /tf alone, and the run holds them once, not twice.
    assert run.rows["pose_observed"] == again.report.event_types["pose_observed"]
    [same] = ingest([ros1.bag], lake, topic_map=no_odom)
    assert same.already
    [forced] = ingest([ros1.bag], lake, topic_map=no_odom, reingest=True)
    assert not forced.already and forced.error is None


def test_lake_add_refuses_a_log_already_in_the_lake(ros1: Recorded, tmp_path: Path) -> None:
    lake = Lake(tmp_path / "lake")
    log_dir = ros1.bag.parent / "log"
    compact_log(log_dir, lake, robot="robot", run="first")
    compact_log(log_dir, lake, robot="robot", run="first")  # the same run again: a no-op
    with pytest.raises(LakeError, match="already in the lake as run 'first'"):
        compact_log(log_dir, lake, robot="robot", run="second")
    assert [r.run for r in lake.runs()] == ["first"]


def test_lake_add_and_ingest_of_one_run_count_once(ros1: Recorded, tmp_path: Path) -> None:
    lake = tmp_path / "lake"
    [result] = ingest([ros1.bag], lake)
    assert result.error is None
    with pytest.raises(LakeError, match="already in the lake as run 'bag-"):
        compact_log(ros1.bag.parent / "log", Lake(lake), robot="robot", run="log")
