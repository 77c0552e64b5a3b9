"""The agent and the stand-in robot as separate processes over real Zenoh and Cyclone DDS give the
same decisions and path lengths as the in-process simulator on a few Table II searches."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from objsearch.agent.catalogue import STORE, DayClock, TaskStarted, decode
from objsearch.events import read_log
from objsearch.runtime.client import AgentClient

from .runtime_fixtures import STARTUP_S, Net, objsearch, stop
from .searches import TRIALS, client_config, in_process, robot_config


def run_over(net: Net, tmp_path: Path, trials: list[tuple[int, str, str]]) -> list[dict[str, Any]]:
    robot = objsearch("robot", "sim", *net.args, log=tmp_path / "robot.txt")
    agent = objsearch(
        "agent",
        "run",
        *net.args,
        *robot_config(tmp_path, ""),
        "--log",
        str(tmp_path / "log"),
        log=tmp_path / "agent.txt",
    )
    out = []
    try:
        with AgentClient(client_config(net)) as client:
            for scene, target, start in trials:
                reset = client.reset_sim(scene, start, timeout_s=STARTUP_S)
                assert reset["ok"]
                r = client.find(
                    target,
                    start=start,
                    scene=scene,
                    timeout_s=STARTUP_S,
                    not_before_ns=reset["stamp_ns"],
                )
                assert r["ok"], r
                out.append({k: r[k] for k in ("success", "path_length", "found", "plans")})
    finally:
        stop(agent)
        stop(robot)
    return out


def test_same_decisions_as_in_process(net: Net, tmp_path: Path) -> None:
    expected = in_process(tmp_path / "inproc")
    before = DayClock.local()
    got = run_over(net, tmp_path, TRIALS)
    after = DayClock.local()
    assert got == expected
    # Every event is in the agent's log, whole tasks only.
    events = list(read_log(tmp_path / "log", store=STORE))
    assert sum(e.type == "task_ended" for e in events) == len(TRIALS)
    # Each search records the local time of day it began (the host's clock, not the stand-in
    # robot's simulated one, which starts in 1970).
    clocks = [decode(e, TaskStarted).clock for e in events if e.type == "task_started"]
    assert len(clocks) == len(TRIALS)
    for clock in clocks:
        assert clock is not None
        assert _week_minute(before) <= _week_minute(clock) <= _week_minute(after) or (
            _week_minute(after) < _week_minute(before)  # the week turned over during the test
        )
    assert {e.type for e in events} >= {"plan_computed", "moved", "detection", "target_found"}


def _week_minute(clock: DayClock) -> int:
    return clock.weekday * 24 * 60 + clock.minute
