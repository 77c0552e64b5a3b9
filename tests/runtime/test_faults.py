"""Faults between the agent and the robot: the agent reports them, its log stays whole, and it
resumes (or fails the search cleanly, saying why)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import read_log
from objsearch.runtime.client import AgentClient

from .runtime_fixtures import STARTUP_S, Net, objsearch, stop
from .searches import client_config, in_process

# claim_s: one agent at a time on its router (searches.ALONE; test_oneagent.py tests the claim)
FAST = (
    "[timeouts]\nrobot_s = 3.0\narrival_s = 1.5\nattempts = 3\ndetections_s = 1.5\nclaim_s = 0.1\n"
)


# Fault handling sits above the transport seam, so one backend is enough (both run end to end in
# test_end_to_end.py); zenoh is the one with a router that can vanish.
pytestmark = pytest.mark.parametrize("net", ["zenoh"], indirect=True)


@pytest.fixture
def zenoh_only(net: Net) -> Net:
    assert net.transport == "zenoh"
    return net


def _agent(net: Net, tmp_path: Path, name: str = "agent") -> subprocess.Popen[bytes]:
    config = tmp_path / "robot.toml"
    config.write_text(FAST)
    return objsearch(
        "agent",
        "run",
        *net.args,
        "--config",
        str(config),
        "--log",
        str(tmp_path / "log"),
        log=tmp_path / f"{name}.txt",
    )


def test_robot_vanishes_then_restarts(zenoh_only: Net, tmp_path: Path) -> None:
    net = zenoh_only
    robot = objsearch("robot", "sim", *net.args, "--exit-after", "2", log=tmp_path / "robot1.txt")
    agent = _agent(net, tmp_path)
    try:
        with AgentClient(client_config(net)) as client:
            reset = client.reset_sim(3, "bathroom-1", timeout_s=STARTUP_S)
            assert reset["ok"]
            failed = client.find(
                "Laptop",
                start="bathroom-1",
                scene=3,
                timeout_s=STARTUP_S,
                not_before_ns=reset["stamp_ns"],
            )
            assert not failed["ok"]
            assert "last heard from the robot" in failed["error"], failed
            assert robot.wait(10) == 3
            # The robot comes back (a fresh process); the agent carries on with the next request.
            robot = objsearch("robot", "sim", *net.args, log=tmp_path / "robot2.txt")
            reset = client.reset_sim(1, "kitchen-1", timeout_s=STARTUP_S)
            assert reset["ok"]
            ok = client.find(
                "Apple",
                start="kitchen-1",
                scene=1,
                timeout_s=STARTUP_S,
                not_before_ns=reset["stamp_ns"],
            )
            assert ok["ok"] and ok["success"] and ok["task_id"] == "task-00002"
    finally:
        stop(agent)
        stop(robot)
    events = list(read_log(tmp_path / "log", store=STORE))
    ended = [e for e in events if e.type == "task_ended"]
    assert [e.payload["success"] for e in ended] == [False, True]
    reason = next(e for e in events if e.type == "search_failed").payload["reason"]
    assert reason.startswith("robot: ") and "last heard from the robot" in reason


def test_dropped_and_malformed_messages(zenoh_only: Net, tmp_path: Path) -> None:
    """Every 5th message lost and one garbage message: same result as a clean run, reported."""
    net = zenoh_only
    robot = objsearch(
        "robot",
        "sim",
        *net.args,
        "--drop-every",
        "5",
        "--malformed-after",
        "2",
        log=tmp_path / "robot.txt",
    )
    agent = _agent(net, tmp_path)
    try:
        with AgentClient(client_config(net)) as client:
            reset = client.reset_sim(1, "bedroom-1", timeout_s=STARTUP_S)
            assert reset["ok"]
            r = client.find(
                "Apple",
                start="bedroom-1",
                scene=1,
                timeout_s=STARTUP_S,
                not_before_ns=reset["stamp_ns"],
            )
    finally:
        stop(agent)
        stop(robot)
    (expected,) = in_process(tmp_path / "inproc", [(1, "Apple", "bedroom-1")])
    assert r["ok"] and {k: r[k] for k in expected} == expected
    assert "dropped a message" in (tmp_path / "agent.txt").read_text()


def test_agent_restart_rebuilds_from_its_log(zenoh_only: Net, tmp_path: Path) -> None:
    net = zenoh_only
    robot = objsearch("robot", "sim", *net.args, log=tmp_path / "robot.txt")
    try:
        with AgentClient(client_config(net)) as client:
            for i, target in enumerate(["Apple", "Cup"]):
                agent = _agent(net, tmp_path, f"agent{i}")
                try:
                    reset = client.reset_sim(1, "kitchen-1", timeout_s=STARTUP_S)
                    assert reset["ok"]
                    r = client.find(
                        target,
                        start="kitchen-1",
                        scene=1,
                        timeout_s=STARTUP_S,
                        not_before_ns=reset["stamp_ns"],
                    )
                    assert r["ok"] and r["task_id"] == f"task-0000{i + 1}"
                finally:
                    assert stop(agent) == 0
    finally:
        stop(robot)
    events = list(read_log(tmp_path / "log", store=STORE))
    assert [e.type for e in events].count("run_started") == 2
    assert [e.type for e in events].count("scene_graph_seeded") == 1
    # Issue 21: one flipped bit in an early record, then a restart from the snapshots. The
    # agent must not start (let alone acknowledge events on top of the damage), nor change a file.
    log = tmp_path / "log"
    data = bytearray((log / "events.log").read_bytes())
    line = 7
    start = [0, *[i + 1 for i, b in enumerate(data) if b == 0x0A]][line - 1]
    data[start + 40] ^= 0x08
    (log / "events.log").write_bytes(bytes(data))
    files = {p: p.read_bytes() for p in log.rglob("*") if p.is_file() and p.name != "LOCK"}
    agent = _agent(net, tmp_path, "agent-damaged")
    assert agent.wait(STARTUP_S) == 2
    said = (tmp_path / "agent-damaged.txt").read_text()
    assert f"objsearch: error: corrupt event log {log / 'events.log'}: line {line} " in said
    assert "is damaged: one bit of it was flipped" in said and "Traceback" not in said
    assert {p: p.read_bytes() for p in log.rglob("*") if p.is_file() and p.name != "LOCK"} == files
