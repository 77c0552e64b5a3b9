"""One event model: every reader folds a log the way the agent did, for every strategy; tasks
are numbered from the log, and a task a crash left open is closed by the restart."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.session import Session, load_context
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import STRATEGIES, RunSpec
from objsearch.events import CorruptLogError, EventLog, fold, read_log
from objsearch.events.lake import TableLake, add_log
from objsearch.replay.analytics import open_analytics
from objsearch.replay.audit import audit
from objsearch.replay.decisions import replay
from objsearch.runtime.liveview import LiveView
from objsearch.sim.longterm import run_schedule
from objsearch.sim.models import SIM_MODELS
from objsearch.sim.placements import Schedule
from objsearch.sim.world import SimClock, SimWorld

HOME = "paper"


def _run(log: Path, name: str) -> None:
    spec = RunSpec.for_home(load_context(HOME).home, name, schedule="table2")
    run_schedule(
        log, spec, scenes=(1, 2), targets=("Apple", "Vase"), starts=("kitchen-2", "bedroom-1")
    )


@pytest.mark.parametrize("name", list(STRATEGIES))
def test_replay_audit_live_view_and_lake_fold_as_the_agent_did(tmp_path: Path, name: str) -> None:
    log = tmp_path / "log"
    _run(log, name)
    agent = fold(read_log(log, store=STORE), AgentState(models=SIM_MODELS))
    assert agent.run is not None and agent.run.strategy == name
    rel = agent.graph().as_table()

    replayed = replay(read_log(log, store=STORE), models=SIM_MODELS)
    assert replayed.decisions and all(d.same for d in replayed.decisions)
    audited = audit(read_log(log, store=STORE), models=SIM_MODELS)
    stale = [a for t in audited.tasks for a in t.anomalies if a.kind == "stale-plan"]
    assert stale == []

    view = LiveView(load_context(HOME), [], models=SIM_MODELS)
    view.fold(read_log(log, store=STORE))
    assert view.agent.graph().as_table() == rel

    lake = TableLake(tmp_path / "lake", store=STORE)
    add_log(log, lake, robot="sim", run=name)
    con = open_analytics(lake.root)
    rows = con.sql("SELECT dynamic, static, rel FROM scene_graph").fetchall()
    if agent.run.relations.model == "eq4":  # the closed form is Eq. 4's, and agrees with the fold
        assert rows and all(abs(rel[d][s] - v) < 1e-9 for d, s, v in rows)
    else:  # no closed form: no rows, rather than values the robot never had
        assert rows == []
    searches = con.execute("SELECT count(*), count(DISTINCT task_id) FROM searches").fetchone()
    assert searches == (agent.tasks.started, agent.tasks.started)


class _Breaks:
    """A world whose robot stops answering after a few moves: the process dies mid-task."""

    def __init__(self, inner: SimWorld, moves: int) -> None:
        self.inner, self.moves = inner, moves

    def __getattr__(self, name: str) -> object:
        return getattr(self.inner, name)

    def navigate(self, *args: object, **kwargs: object) -> object:
        self.moves -= 1
        if self.moves < 0:
            raise KeyboardInterrupt("killed")
        return self.inner.navigate(*args, **kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize("moves", [0, 2, 5])
def test_a_task_left_open_by_a_crash_is_aborted_on_restart_and_its_id_never_reused(
    tmp_path: Path, moves: int
) -> None:
    ctx = load_context(HOME)
    spec = RunSpec.for_home(ctx.home, "wpl", schedule="table2")
    scene = Schedule.load(ctx.home, "table2").scenes[1]
    log = tmp_path / "log"

    def world(start: str, clock: SimClock) -> SimWorld:
        return SimWorld(ctx.home, ctx.navmap, scene, ctx.home.start(start), clock=clock)

    session = Session.start(ctx, log, spec)
    clock = SimClock(session.resume_time_ns)
    assert session.search(world("kitchen-1", clock), "Cup", "kitchen-1").task_id == "task-00001"
    with pytest.raises(KeyboardInterrupt):
        session.search(_Breaks(world("bedroom-1", clock), moves), "Vase", "bedroom-1")  # type: ignore[arg-type]
    session.log.close()  # the process is gone; the kernel closes its files

    session = Session.start(ctx, log, spec)
    try:
        clock = SimClock(session.resume_time_ns)
        result = session.search(world("bedroom-1", clock), "Vase", "bedroom-1")
    finally:
        session.close()
    assert result.task_id == "task-00003"
    events = list(read_log(log, store=STORE))
    started = [e.task_id for e in events if e.type == "task_started"]
    assert started == ["task-00001", "task-00002", "task-00003"]
    aborted = [e for e in events if e.type == "task_aborted"]
    assert [(e.task_id, e.payload["reason"]) for e in aborted] == [("task-00002", "restart")]
    moved = sum(
        e.payload["metres"] for e in events if e.type == "moved" and e.task_id == "task-00002"
    )
    assert aborted[0].payload["path_length"] == pytest.approx(moved, abs=1e-4)

    lake = TableLake(tmp_path / "lake", store=STORE)
    add_log(log, lake, robot="sim", run="r")
    con = open_analytics(lake.root)
    rows = con.sql("SELECT task_id, success, aborted FROM searches ORDER BY task_id").fetchall()
    assert rows == [
        ("task-00001", True, False),
        ("task-00002", False, True),
        ("task-00003", True, False),
    ]


def test_restart_from_a_snapshot_gives_the_state_a_full_fold_gives(tmp_path: Path) -> None:
    ctx = load_context(HOME)
    log, snaps = tmp_path / "log", tmp_path / "snapshots"
    _run(log, "wpl-neg-decay")
    full = fold(read_log(log, store=STORE), AgentState())
    session = Session.open(ctx, log, snapshot_dir=snaps)
    session.close()  # writes the snapshot
    session = Session.open(ctx, log, snapshot_dir=snaps)
    try:
        restored = session.state
        assert restored.graph().as_table() == full.graph().as_table()
        assert restored.tasks.next_task_id() == full.tasks.next_task_id()
        assert restored.run == full.run
    finally:
        session.close()


def _flip_bit_in_record(log: Path, seq: int, *, in_checksum: bool = False) -> None:
    path = log / "events.log"
    data = bytearray(path.read_bytes())
    start = 0
    for _ in range(seq - 1):
        start = data.index(b"\n", start) + 1
    end = data.index(b"\n", start)
    at = end - 3 if in_checksum else start + (end - start) // 2
    data[at] ^= 0x04
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("in_checksum", [False, True])
def test_a_restart_from_a_snapshot_refuses_damage_anywhere_before_it(
    tmp_path: Path, in_checksum: bool
) -> None:
    """The fast restart checks every acknowledged byte (by its seals): one flipped bit in an
    early record stops the agent before it appends anything on top of it."""
    ctx = load_context(HOME)
    log, snaps = tmp_path / "log", tmp_path / "snapshots"
    _run(log, "wpl")
    Session.open(ctx, log, snapshot_dir=snaps).close()  # writes and attests the snapshot
    clean = Session.open(ctx, log, snapshot_dir=snaps)  # a clean restart, from the snapshot
    clean.close()
    assert clean.state.last_seq > 71
    _flip_bit_in_record(log, 71, in_checksum=in_checksum)
    before = {p: p.read_bytes() for d in (log, snaps) for p in d.iterdir() if p.is_file()}
    spec = RunSpec.for_home(ctx.home, "wpl", schedule="table2")
    with pytest.raises(CorruptLogError, match="line 71 "):
        Session.start(ctx, log, spec, snapshot_dir=snaps)
    with pytest.raises(CorruptLogError, match="line 71 "):  # a session that appends nothing
        Session.open(ctx, log, snapshot_dir=snaps).close()
    assert {p: p.read_bytes() for d in (log, snaps) for p in d.iterdir() if p.is_file()} == before


def test_a_log_keeps_the_relation_model_of_its_first_run(tmp_path: Path) -> None:
    ctx = load_context(HOME)
    Session.start(ctx, tmp_path, RunSpec.for_home(ctx.home, "wpl")).close()
    Session.start(ctx, tmp_path, RunSpec.for_home(ctx.home, "epl")).close()  # same fold
    with pytest.raises(Exception, match="needs a new log"):
        Session.start(ctx, tmp_path, RunSpec.for_home(ctx.home, "wpl-neg"))
    with EventLog.open(tmp_path, "robot", store=STORE) as log:  # and the refused run wrote nothing
        assert log.last_seq == 3  # run_started, scene_graph_seeded, run_started


SCHEDULE_RUNNER = r"""
import sys
from pathlib import Path
from objsearch.agent.session import load_context
from objsearch.agent.strategies import RunSpec
from objsearch.sim.longterm import run_schedule

spec = RunSpec.for_home(load_context("paper").home, "wpl", schedule="table2")
print("ready", flush=True)
run_schedule(Path(sys.argv[1]), spec, scenes=(1, 2, 3))
"""


@pytest.mark.parametrize("delay_s", [0.7, 1.6, 2.9])
def test_sigkill_mid_schedule_then_restart_never_repeats_a_task(
    tmp_path: Path, delay_s: float
) -> None:
    import signal
    import subprocess
    import sys
    import time

    log = tmp_path / "log"
    proc = subprocess.Popen(
        [sys.executable, "-c", SCHEDULE_RUNNER, str(log)], stdout=subprocess.PIPE, text=True
    )
    assert proc.stdout is not None and proc.stdout.readline() == "ready\n"
    time.sleep(delay_s)
    proc.send_signal(signal.SIGKILL)
    proc.wait()

    ctx = load_context(HOME)
    spec = RunSpec.for_home(ctx.home, "wpl", schedule="table2")
    run_schedule(log, spec, scenes=(4,), targets=("Cup",), starts=("kitchen-1", "bedroom-1"))
    events = list(read_log(log, store=STORE))
    started = [str(e.task_id) for e in events if e.type == "task_started"]
    closed = [str(e.task_id) for e in events if e.type in ("task_ended", "task_aborted")]
    assert len(started) == len(set(started))  # no task id ever repeats
    assert sorted(closed) == sorted(started)  # every task ends exactly once, aborted or not
    lake = TableLake(tmp_path / "lake", store=STORE)
    add_log(log, lake, robot="sim", run="r")
    rows = open_analytics(lake.root).execute(
        "SELECT count(*), count(DISTINCT task_id) FROM searches"
    )
    assert rows.fetchone() == (len(started), len(started))
