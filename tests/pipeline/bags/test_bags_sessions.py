"""One recording session is one run: split bags, any order, other formats, one clock, re-ingest."""

from __future__ import annotations

import datetime as dt
import random
from pathlib import Path

import pyarrow.compute as pc
import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events.lake import LakeError, TableLake, add_log
from objsearch.pipeline.bags.formats import BagFormat
from objsearch.pipeline.bags.ingest import ingest
from objsearch.pipeline.bags.lake import FleetBagLake

from .bag_fixtures import Recorded, record_run
from .splitter import rerecord_ros1, split_ros1

BAG_CLOCK_2026 = int(dt.datetime(2026, 1, 1, tzinfo=dt.UTC).timestamp() * 1e9)


@pytest.fixture(scope="module")
def whole(ros1: Recorded, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder lake of the whole recording ingested at once (what the pieces must equal)."""
    lake = tmp_path_factory.mktemp("whole") / "lake"
    ingest([ros1.bag], lake)
    return lake


def _content(lake: Path) -> tuple[list[tuple[str, int, str]], dict[str, int], list[int]]:
    """What a run says, ids of derived events aside: agent events, rows per type, pose times."""
    runs = TableLake(lake, store=STORE).runs()
    assert len(runs) == 1, [r.run for r in runs]
    tables = TableLake(lake, store=STORE).read_tables(runs[0])
    agent = sorted(
        (e.event_id, e.time_ns, e.type)
        for e in TableLake(lake, store=STORE).read_events(runs[0])
        if not e.stream.startswith("bag:")
    )
    rows = {t: table.num_rows for t, table in tables.items()}
    poses = sorted(tables["pose_observed"]["time_ns"].to_pylist())
    return agent, rows, poses


def test_split_pieces_in_any_order_are_one_run(
    pieces: list[Path], tmp_path: Path, whole: Path
) -> None:
    shuffled = pieces[:]
    random.Random(3).shuffle(shuffled)
    results = ingest(shuffled, tmp_path / "split")
    assert [r.error for r in results] == [None] * len(pieces)
    assert _content(tmp_path / "split") == _content(whole)
    [run] = TableLake(tmp_path / "split", store=STORE).runs()
    assert run.date == "2026-01-01" and run.identity.get("run_id")
    assert not list((tmp_path / "split").glob("robot=*/date=1970-*"))


def test_pieces_at_different_times_first_one_last(
    pieces: list[Path], tmp_path: Path, whole: Path
) -> None:
    lake = tmp_path / "lake"
    later = [ingest([p], lake) for p in pieces[1:]]  # the first piece (run_started) comes last
    assert all(r.error is None and r.committed > 0 for [r] in later)
    [first] = ingest([pieces[0]], lake)
    assert first.error is None and "merged into run" in first.note
    assert _content(lake) == _content(whole)
    kinds = {f.kind for f in TableLake(lake, store=STORE).data_files()}
    assert any(kind.startswith("derived.searches.") for kind in kinds)
    assert len(FleetBagLake(lake).known_pieces()) == len(pieces)


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
    from rosbags.typesys import Stores, get_typestore

    empty = tmp_path / "empty.bag"
    with Writer(empty) as writer:
        writer.add_connection(
            "/chatter", "std_msgs/msg/String", typestore=get_typestore(Stores.ROS1_NOETIC)
        )
    [result] = ingest([empty], tmp_path / "lake")
    assert result.error is None and result.committed == 0 and "nothing committed" in result.note
    assert TableLake(tmp_path / "lake", store=STORE).runs() == []


def test_one_clock_per_run(ros1: Recorded, tmp_path: Path) -> None:
    [result] = ingest([ros1.bag], tmp_path / "lake")
    assert result.report is not None and result.report.clock_offset_ns == BAG_CLOCK_2026
    [run] = TableLake(tmp_path / "lake", store=STORE).runs()
    tables = TableLake(tmp_path / "lake", store=STORE).read_tables(run)
    start, end = result.report.start_ns, result.report.end_ns
    assert start is not None and end is not None
    for event_type, table in tables.items():
        times = table["time_ns"]
        assert pc.min(times).as_py() >= start and pc.max(times).as_py() <= end, event_type
    logged = {e.event_id: e.time_ns for e in ros1.log}
    for e in TableLake(tmp_path / "lake", store=STORE).read_events(run):
        if e.event_id in logged:
            assert e.time_ns == logged[e.event_id] + BAG_CLOCK_2026


def test_lake_add_refuses_a_log_already_in_the_lake(ros1: Recorded, tmp_path: Path) -> None:
    lake = TableLake(tmp_path / "lake", store=STORE)
    log_dir = ros1.bag.parent / "log"
    add_log(log_dir, lake, robot="robot", run="first")
    add_log(log_dir, lake, robot="robot", run="first")  # the same run again: a no-op
    with pytest.raises(LakeError, match="already in the lake as run 'first'"):
        add_log(log_dir, lake, robot="robot", run="second")
    assert [r.run for r in lake.runs()] == ["first"]


def test_lake_add_and_ingest_of_one_run_count_once(ros1: Recorded, tmp_path: Path) -> None:
    lake = tmp_path / "lake"
    [result] = ingest([ros1.bag], lake)
    assert result.error is None
    with pytest.raises(LakeError, match="already in the lake as run 'bag-"):
        add_log(ros1.bag.parent / "log", TableLake(lake, store=STORE), robot="robot", run="log")


# -- recordings no piece of which holds run_started (the recorder started after the agent) ---


def _agent_ids(lake: Path) -> list[str]:
    return [
        e.event_id
        for run in TableLake(lake, store=STORE).runs()
        for e in TableLake(lake, store=STORE).read_events(run)
        if not e.stream.startswith("bag:")
    ]


def _all_ids(lake: Path) -> list[str]:
    return [
        i
        for run in TableLake(lake, store=STORE).runs()
        for table in TableLake(lake, store=STORE).read_tables(run).values()
        for i in table["event_id"].to_pylist()
    ]


def test_pieces_without_run_started_in_any_order_are_one_run(
    ros1: Recorded, pieces: list[Path], tmp_path: Path, whole: Path
) -> None:
    late = pieces[1:]  # what a recorder started after the agent holds
    for r in ingest(late, tmp_path / "a"):
        assert r.error is None and r.report is not None
        assert "run_started" not in r.report.event_types
    assert len(TableLake(tmp_path / "a", store=STORE).runs()) == 1
    shuffled = late[::-1]
    random.Random(5).shuffle(shuffled)
    ingest(shuffled, tmp_path / "b")
    assert _content(tmp_path / "b") == _content(tmp_path / "a")
    ingest([pieces[0]], tmp_path / "b")  # the first piece after all: the run id is known now
    assert _content(tmp_path / "b") == _content(whole)
    ids = _all_ids(tmp_path / "b")
    assert len(ids) == len(set(ids))
    first_piece = {e.event_id for e in ros1.log} - set(_agent_ids(tmp_path / "a"))
    assert first_piece and {e.type for e in ros1.log if e.event_id in first_piece} >= {
        "run_started"
    }


def test_pieces_of_two_recordings_stay_two_runs(
    ros1: Recorded, pieces: list[Path], tmp_path: Path
) -> None:
    other = record_run(tmp_path / "other", BagFormat.ROS1, seed=1)
    other_pieces = split_ros1(other.bag, tmp_path / "other-split", duration_s=60.0)
    ingest([*pieces[1:], *other_pieces[1:]], tmp_path / "lake")
    runs = TableLake(tmp_path / "lake", store=STORE).runs()
    assert len(runs) == 2
    ids = _all_ids(tmp_path / "lake")
    assert len(ids) == len(set(ids))


def test_pieces_of_a_compacted_log_are_refused_naming_it(
    ros1: Recorded, pieces: list[Path], tmp_path: Path
) -> None:
    lake = tmp_path / "lake"
    add_log(ros1.bag.parent / "log", TableLake(lake, store=STORE), robot="robot", run="agent-log")
    for result in ingest(pieces[1:], lake):
        assert result.error is not None and "run 'agent-log' of robot 'robot'" in result.error
    ids = _all_ids(lake)
    assert len(ids) == len(set(ids)) == len(ros1.log)


RECORDER_CLOCK = int(dt.datetime(2026, 12, 2, tzinfo=dt.UTC).timestamp() * 1e9)


def test_a_rerecorded_bag_is_on_one_clock(ros1: Recorded, tmp_path: Path, whole: Path) -> None:
    """``rosbag play -r 20`` → ``rosbag record``: receive times 20× faster, on another day; the
    header stamps kept. The run is on the agent's clock, its poses where the original's are."""
    replayed = rerecord_ros1(ros1.bag, tmp_path / "replayed.bag", rate=20, start_ns=RECORDER_CLOCK)
    [result] = ingest([replayed], tmp_path / "lake")
    assert result.report is not None and result.report.clock is not None
    assert result.report.clock.rate == pytest.approx(20, rel=1e-6)
    agent, rows, poses = _content(tmp_path / "lake")
    assert (agent, rows) == _content(whole)[:2]
    original = _content(whole)[2]
    assert max(abs(a - b) for a, b in zip(poses, original, strict=True)) < 1_000  # ns
    [run] = TableLake(tmp_path / "lake", store=STORE).runs()
    assert run.date == "2026-01-01"
    received = TableLake(tmp_path / "lake", store=STORE).read_tables(run)["pose_observed"][
        "recorded_at_ns"
    ]
    assert pc.min(received).as_py() >= RECORDER_CLOCK


def test_a_rerecorded_split_recording_is_one_run_on_one_clock(
    ros1: Recorded, tmp_path: Path, whole: Path
) -> None:
    replayed = rerecord_ros1(ros1.bag, tmp_path / "replayed.bag", rate=20, start_ns=RECORDER_CLOCK)
    late = split_ros1(replayed, tmp_path / "split", duration_s=3.0)[1:]
    assert len(late) >= 2
    results = ingest(late[::-1], tmp_path / "lake")
    assert [r.error for r in results] == [None] * len(late)
    [run] = TableLake(tmp_path / "lake", store=STORE).runs()
    assert run.date == "2026-01-01"
    events = TableLake(tmp_path / "lake", store=STORE).read_events(run)
    # Every derived event is where the original bag has it (the receive clock mapped back).
    derived = {
        (e.type, e.time_ns)
        for r in TableLake(whole, store=STORE).runs()
        for e in TableLake(whole, store=STORE).read_events(r)
        if e.stream.startswith("bag:")
    }
    for e in events:
        if e.stream.startswith("bag:"):
            near = [t for typ, t in derived if typ == e.type and abs(t - e.time_ns) < 1_000]
            assert near, (e.type, e.time_ns)


def test_pieces_of_odometry_alone_join_their_recording(
    ros1: Recorded, tmp_path: Path, whole: Path
) -> None:
    """Split every 5 s, most pieces hold odometry and TF alone (the robot driving between
    events); in any order, with or without the piece holding run_started, one run."""
    cut = split_ros1(ros1.bag, tmp_path / "split", duration_s=5.0)
    odometry_only = [
        p
        for r, p in zip(ingest(cut, tmp_path / "a"), cut, strict=True)
        if r.report and "pose_observed" in r.report.event_types and len(r.report.event_types) == 1
    ]
    assert len(odometry_only) >= 3
    assert _content(tmp_path / "a") == _content(whole)
    [run] = TableLake(tmp_path / "a", store=STORE).runs()
    assert run.identity.get("run_id")
    shuffled = cut[:]
    random.Random(7).shuffle(shuffled)
    ingest(shuffled, tmp_path / "b")
    assert _content(tmp_path / "b") == _content(whole)
    late = cut[1:]
    random.Random(8).shuffle(late)
    ingest(late, tmp_path / "c")
    assert len(TableLake(tmp_path / "c", store=STORE).runs()) == 1
    ids = _all_ids(tmp_path / "c")
    assert len(ids) == len(set(ids))
