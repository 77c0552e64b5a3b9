"""A recording made by Debian's ROS 1 tools (fixtures/rerecorded/README.md): ``rosbag play -r 20``
of one of our bags, recorded by ``rosbag record --split`` that started after the agent, so no
piece holds ``run_started``; receive times on the recorder's clock, header stamps on the agent's."""

from __future__ import annotations

import datetime as dt
import itertools
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pytest
from rosbags.highlevel import AnyReader

from objsearch.agent.catalogue import STORE
from objsearch.cli import main
from objsearch.events import Event, read_log
from objsearch.events.lake import TableLake, add_log
from objsearch.pipeline.bags.ingest import ingest
from objsearch.pipeline.bags.read import read_bag

FIXTURES = Path(__file__).parent / "fixtures" / "rerecorded"
PIECES = [FIXTURES / "pieces" / f"piece_{i}.bag" for i in range(7)]
AGENT_PIECES = [PIECES[i] for i in (1, 2, 5)]  # the others hold odometry/TF alone, or nothing
SIM_START_NS = int(dt.datetime(2026, 1, 1, tzinfo=dt.UTC).timestamp() * 1e9)
RECORDER_DAY_NS = int(dt.datetime(2026, 12, 2, tzinfo=dt.UTC).timestamp() * 1e9)
#: What a receive time mapped onto the agent's clock may be off by: the recorder got some
#: messages up to 14 ms late, × 20 (the fit's largest residual over the agent's events was
#: 10.5 ms; over the poses 272 ms). Less than the odometry's period (0.5 s).
JITTER_NS = 400_000_000


def _log() -> list[Event]:
    return list(read_log(FIXTURES / "log", store=STORE))


def _tables(lake: Path) -> dict[str, pa.Table]:
    """Every run's tables, concatenated per event type."""
    by_type: dict[str, list[pa.Table]] = {}
    for run in TableLake(lake, store=STORE).runs():
        for event_type, table in TableLake(lake, store=STORE).read_tables(run).items():
            by_type.setdefault(event_type, []).append(table)
    return {t: pa.concat_tables(ts, promote_options="default") for t, ts in by_type.items()}


def _ids(lake: Path) -> list[str]:
    return [i for t in _tables(lake).values() for i in t["event_id"].to_pylist()]


def test_the_fixture_is_what_the_readme_says() -> None:
    agent = [e for p in PIECES for e in read_bag(p).agent]
    assert agent and "run_started" not in {e.type for e in agent}
    with AnyReader([PIECES[1]]) as reader:
        first_received = next(t for _, t, _ in reader.messages())
    assert first_received > RECORDER_DAY_NS  # received on the recorder's clock


@pytest.mark.parametrize(
    "order", [(0, 1, 2, 3, 4, 5, 6), (6, 5, 4, 3, 2, 1, 0), (5, 3, 0, 6, 1, 4, 2)]
)
def test_split_pieces_without_run_started_are_one_run_on_one_clock(
    order: tuple[int, ...], tmp_path: Path
) -> None:
    results = ingest([PIECES[i] for i in order], tmp_path / "lake")
    assert [r.error for r in results] == [None] * len(PIECES)
    [run] = TableLake(tmp_path / "lake", store=STORE).runs()
    assert run.date == "2026-01-01"
    ids = _ids(tmp_path / "lake")
    assert len(ids) == len(set(ids))
    events = TableLake(tmp_path / "lake", store=STORE).read_events(run)
    agent = {e.event_id: e for e in events if not e.stream.startswith("bag:")}
    logged = {e.event_id: e for e in _log() if e.seq >= 3}  # the recorder missed seqs 1 and 2
    assert agent.keys() == logged.keys()
    for event_id, e in agent.items():
        assert e.time_ns == logged[event_id].time_ns + SIM_START_NS
    tasks = [e.task_id for e in events if e.type == "task_ended"]
    assert len(tasks) == 2 and {e.task_id for e in events if e.type == "task_started"} == set(tasks)
    # One clock: every event of the run lies within the agent's session, none on the recorder's.
    first, last = min(e.time_ns for e in agent.values()), max(e.time_ns for e in agent.values())
    for e in events:
        assert first - JITTER_NS <= e.time_ns <= last + JITTER_NS, (e.type, e.time_ns)


def test_the_pieces_give_the_poses_of_the_bag_that_was_played(tmp_path: Path) -> None:
    ingest(PIECES, tmp_path / "pieces")
    ingest([FIXTURES / "run.bag"], tmp_path / "whole")
    pieces = sorted(_tables(tmp_path / "pieces")["pose_observed"]["time_ns"].to_pylist())
    whole = _tables(tmp_path / "whole")["pose_observed"]
    # The recording began 60 s into the session (sim time): compare from there on.
    recorded = pc.greater_equal(whole["time_ns"], SIM_START_NS + 60 * 10**9)
    expected = sorted(whole.filter(recorded)["time_ns"].to_pylist())
    assert len(pieces) == len(expected) == 151
    # Each pose at its odometry message's header stamp: exactly the played bag's times (from
    # receive times mapped onto the agent's clock they were 26 ms off, median; 272 ms at worst).
    assert pieces == expected
    # recorded_at_ns keeps when the recorder received each pose.
    received = _tables(tmp_path / "pieces")["pose_observed"]["recorded_at_ns"]
    assert pc.min(received).as_py() > RECORDER_DAY_NS


def test_pieces_of_a_log_already_in_the_lake_are_refused_naming_it(tmp_path: Path) -> None:
    lake = tmp_path / "lake"
    add_log(FIXTURES / "log", TableLake(lake, store=STORE), robot="robot", run="agent-log")
    for order in itertools.islice(itertools.permutations(AGENT_PIECES), 2):
        results = ingest(list(order), lake)
        for r in results:
            assert r.error is not None and "run 'agent-log' of robot 'robot'" in r.error
            assert "count its events twice" in r.error
    ids = _ids(lake)
    assert len(ids) == len(set(ids)) == len(_log())


def test_a_log_whose_pieces_are_already_in_the_lake_is_refused_naming_them(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lake = tmp_path / "lake"
    ingest(AGENT_PIECES, lake)
    [run] = TableLake(lake, store=STORE).runs()
    before = _ids(lake)
    args = ["lake", "add", str(FIXTURES / "log"), "--lake", str(lake), "--robot", "robot"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("objsearch: error: ") and f"run {run.run!r}" in err
    assert "count those events twice" in err
    assert _ids(lake) == before and len(before) == len(set(before))


def test_a_piece_of_a_recording_refused_leaves_its_session_out(tmp_path: Path) -> None:
    """The same through the CLI: exit 2, `objsearch: error:` naming the run."""
    lake = tmp_path / "lake"
    add_log(FIXTURES / "log", TableLake(lake, store=STORE), robot="robot", run="agent-log")
    assert main(["ingest", str(PIECES[2]), "--lake", str(lake), "--no-progress"]) == 2
    assert [r.run for r in TableLake(lake, store=STORE).runs()] == ["agent-log"]


def test_an_empty_last_piece_is_accepted_as_empty(tmp_path: Path) -> None:
    report = read_bag(PIECES[6]).report
    assert report.claims_complete and report.events == 0 and not report.damaged
    assert not any("index" in note for note in report.notes)
    [result] = ingest([PIECES[6]], tmp_path / "lake")
    assert result.error is None and "nothing committed" in result.note


def test_liveview_of_a_bag_run_stamps_the_bags_clock(tmp_path: Path) -> None:
    lake = tmp_path / "lake"
    ingest([FIXTURES / "run.bag"], lake)
    [run] = TableLake(lake, store=STORE).runs()
    out = tmp_path / "view.mcap"
    assert main(["liveview", str(lake), "--run", run.run, "--mcap", str(out)]) == 0
    with AnyReader([out]) as reader:
        stamps = [t for _, t, _ in reader.messages()]
    first = min(e.time_ns for e in TableLake(lake, store=STORE).read_events(run))
    assert min(stamps) == first == SIM_START_NS


def test_liveview_refuses_a_stamp_ros_time_cannot_carry(tmp_path: Path) -> None:
    from objsearch.agent.errors import ObjsearchError
    from objsearch.runtime.livesinks import McapSink
    from objsearch.runtime.liveview import render

    sink = McapSink(tmp_path / "view.mcap", compress=False)
    with pytest.raises(ObjsearchError, match="outside ROS time"):
        render(read_log(FIXTURES / "log", store=STORE), [sink], clock_offset_ns=3 * 10**18)
    sink.abort()
    assert not (tmp_path / "view.mcap").exists()


def test_a_bag_and_its_rerecording_in_one_lake_are_one_run_on_one_clock(tmp_path: Path) -> None:
    """run.bag (receive time = stamp) proves the run id; the re-recorded pieces join it. Only
    the pieces' receive times are mapped: run.bag's rows stay where they are. Each pose and
    detection is kept once: the re-recording's carry the same header stamps and contents."""
    lake = tmp_path / "lake"
    results = ingest([FIXTURES / "run.bag", *PIECES], lake)
    assert [r.error for r in results] == [None] * (len(PIECES) + 1)
    assert len(TableLake(lake, store=STORE).runs()) == 1
    ids = _ids(lake)
    assert len(ids) == len(set(ids))
    times = [t for table in _tables(lake).values() for t in table["time_ns"].to_pylist()]
    assert min(times) >= SIM_START_NS and max(times) <= SIM_START_NS + 134 * 10**9
    ingest([FIXTURES / "run.bag"], tmp_path / "whole")
    for event_type in ("pose_observed", "objects_detected"):
        whole = _tables(tmp_path / "whole")[event_type]
        both = _tables(lake)[event_type]
        assert sorted(both["time_ns"].to_pylist()) == sorted(whole["time_ns"].to_pylist())
        keep = [c for c in whole.column_names if c not in ("event_id", "stream", "seq")]
        assert both.select(keep).sort_by("time_ns").equals(whole.select(keep).sort_by("time_ns"))
