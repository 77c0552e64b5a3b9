"""Nav2's navigate_to_pose action and the pose from TF, with the agent and the stand-in robot as
separate processes: the same decisions and path lengths as the in-process simulator, and faults
of the action (rejected, aborted, stuck, silent) ending a search cleanly with a reason."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import read_log
from objsearch.runtime.client import AgentClient

from .runtime_fixtures import Net, objsearch, stop
from .searches import (
    ACTION,
    TF,
    TRIALS,
    client_config,
    decisions,
    find_after_reset,
    in_process,
    robot_config,
)

FAST = "[timeouts]\nrobot_s = 3.0\narrival_s = 1.5\nattempts = 3\ndetections_s = 1.5\n"


@pytest.mark.parametrize(
    ("net", "config"),
    [("zenoh", ACTION), ("dds", ACTION + TF), ("zenoh", TF)],
    ids=["zenoh-action", "dds-action-tf", "zenoh-tf"],
    indirect=["net"],
)
def test_same_decisions_as_in_process(net: Net, config: str, tmp_path: Path) -> None:
    expected = in_process(tmp_path / "inproc")
    args = [*net.args, *robot_config(tmp_path, config)]
    robot = objsearch("robot", "sim", *args, log=tmp_path / "robot.txt")
    agent = objsearch(
        "agent", "run", *args, "--log", str(tmp_path / "log"), log=tmp_path / "agent.txt"
    )
    got = []
    try:
        with AgentClient(client_config(net)) as client:
            for scene, target, start in TRIALS:
                r = find_after_reset(client, scene, target, start)
                assert r["ok"], r
                got.append(decisions(r))
    finally:
        stop(agent)
        stop(robot)
    assert got == expected


@pytest.mark.parametrize("net", ["zenoh"], indirect=True)
def test_rejected_aborted_and_stuck_goals(net: Net, tmp_path: Path) -> None:
    """Goal 1 rejected and goal 2 aborted: two searches fail saying so. Goal 3 is never finished:
    the agent cancels it (cancel_goal) and sends the waypoint again; that search succeeds with
    the simulator's decisions. The paper's method: its Eq. 4 learns nothing from the two failed
    searches, so a fresh in-process log decides the third alike (a belief counts their looks)."""
    args = [*net.args, *robot_config(tmp_path, ACTION + FAST)]
    faults = ["--reject-after", "1", "--abort-after", "2", "--stall-after", "3"]
    robot = objsearch("robot", "sim", *args, *faults, log=tmp_path / "robot.txt")
    agent = objsearch(
        "agent",
        "run",
        *args,
        "--strategy",
        "wpl",
        "--log",
        str(tmp_path / "log"),
        log=tmp_path / "agent.txt",
    )
    try:
        with AgentClient(client_config(net)) as client:
            rejected = find_after_reset(client, 1, "Apple", "kitchen-1")
            aborted = find_after_reset(client, 1, "Apple", "kitchen-1")
            stuck = find_after_reset(client, 1, "Apple", "bedroom-1")
    finally:
        stop(agent)
        stop(robot)
    assert not rejected["ok"] and "rejected the /navigate_to_pose goal" in rejected["error"]
    assert not aborted["ok"] and "ended aborted" in aborted["error"], aborted
    (expected,) = in_process(tmp_path / "inproc", [(1, "Apple", "bedroom-1")], strategy="wpl")
    assert stuck["ok"], stuck
    assert decisions(stuck) == expected
    assert "cancel_goal answered 0" in (tmp_path / "agent.txt").read_text()
    events = list(read_log(tmp_path / "log", store=STORE))
    reasons = [e.payload["reason"] for e in events if e.type == "search_failed"]
    assert len(reasons) == 2 and all(r.startswith("robot: ") for r in reasons)
    ended = [e.payload["success"] for e in events if e.type == "task_ended"]
    assert ended == [False, False, True]


@pytest.mark.parametrize("net", ["zenoh"], indirect=True)
def test_robot_never_answers_send_goal(net: Net, tmp_path: Path) -> None:
    args = [*net.args, *robot_config(tmp_path, ACTION + FAST)]
    robot = objsearch("robot", "sim", *args, "--mute-after", "2", log=tmp_path / "robot.txt")
    agent = objsearch(
        "agent", "run", *args, "--log", str(tmp_path / "log"), log=tmp_path / "agent.txt"
    )
    try:
        with AgentClient(client_config(net)) as client:
            r = find_after_reset(client, 1, "Apple", "bedroom-1")
    finally:
        stop(agent)
        stop(robot)
    assert not r["ok"] and "no answer to /navigate_to_pose goal" in r["error"], r
    assert "(send_goal) within 3 s" in r["error"]
    events = list(read_log(tmp_path / "log", store=STORE))
    assert [e.type for e in events][-2:] == ["search_failed", "task_ended"]
