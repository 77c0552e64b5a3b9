"""The agent's typed interfaces over ``--transport ros2``, asked by a ROS user's own client: a
script of plain rclpy and the generated ``objsearch_msgs`` (``ros_user.py``) run as a process
of its own, so nothing of objsearch is imported on the client's side. The agent and the
stand-in robot are nodes of this process (each its own rclpy context)."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import read_log
from objsearch.runtime.agent_node import AgentNode
from objsearch.runtime.config import RuntimeConfig, Timeouts
from objsearch.runtime.requests import WhereRequest
from objsearch.runtime.standin import StandInRobot
from objsearch.runtime.transport import Backend, TransportConfig

from .runtime_fixtures import STARTUP_S, next_domain

pytest.importorskip("rclpy")

USER = Path(__file__).with_name("ros_user.py")
#: Ten searches, each from where the last one left the robot (the stand-in's base placements).
TARGETS = ["Apple", "Cup", "Bowl", "Apple", "Cup", "Bowl", "Apple", "Cup", "Bowl", "Apple"]


def config(domain: int, node: str) -> RuntimeConfig:
    # One agent on its own domain: no claim to wait out (test_oneagent.py tests the claim).
    return RuntimeConfig(
        transport=TransportConfig(backend=Backend.ROS2, domain_id=domain, node=node),
        timeouts=replace(Timeouts(), claim_s=0.1),
    )


@contextmanager
def agent_and_robot(tmp_path: Path, domain: int) -> Iterator[AgentNode]:
    robot = StandInRobot(config(domain, "objsearch_robot"))
    robot_thread = threading.Thread(target=robot.run, name="robot", daemon=True)
    robot_thread.start()
    agent = None
    try:
        agent = AgentNode(config(domain, "objsearch"), tmp_path / "log")
        agent_thread = threading.Thread(target=agent.run, name="agent", daemon=True)
        agent_thread.start()
        yield agent
        agent.stop()
        agent_thread.join(STARTUP_S)
    finally:
        if agent is not None:
            agent.stop()
        robot.stop()
        robot_thread.join(STARTUP_S)


def ros_user(*args: str) -> dict[str, Any]:
    done = subprocess.run(
        [sys.executable, str(USER), *args], capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-3000:]
    out: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["objsearch_modules"] == []  # the client is a ROS user's, not ours
    return out


def test_find_object_action_and_where_service_for_a_ros_user(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    domain = next_domain()
    with caplog.at_level("INFO", "objsearch"), agent_and_robot(tmp_path, domain) as agent:
        found = ros_user("find", str(domain), ",".join(TARGETS))
        asked = ros_user("where", str(domain), "Apple", "100")
        where_json = agent.answer_where(WhereRequest(id="test", target="Apple"))
    goals, cancel = found["goals"], found["cancelled"]
    assert [g["status"] for g in goals] == [4] * 10, goals
    assert all(g["found"] and g["feedback"] >= 1 for g in goals), goals
    assert all(g["feedback_rooms"] and g["feedback_belief"] >= 1 for g in goals), goals
    # Every result names its search in the log, and where the target was found.
    events = list(read_log(tmp_path / "log", store=STORE))
    ended = {e.task_id: e.payload for e in events if e.type == "task_ended"}
    for g in goals:
        assert ended[g["task_id"]]["success"] is True
        assert ended[g["task_id"]]["path_length"] == round(g["path_length"], 4)
        assert g["room"] and g["position"] != [0.0, 0.0]
    # The cancelled one ends cleanly: CANCELED, its task closed in the log, and said in the log.
    assert cancel["accepted"] and cancel["return_code"] == 0 and cancel["status"] == 5, cancel
    assert cancel["error"].startswith("cancelled by the client (FindObject goal")
    failed = [e for e in events if e.type == "search_failed" and e.task_id == cancel["task_id"]]
    assert [e.payload["reason"] for e in failed] == [f"cancelled: {cancel['error']}"]
    assert ended[cancel["task_id"]]["success"] is False
    assert "cancel requested by the client" in caplog.text
    # 100 Where calls, 100 typed answers equal to the memory's own answer.
    answers = asked["answers"]
    assert len(answers) == 100 and all(a["ok"] and a["target"] == "Apple" for a in answers)
    expected = where_json["answer"]
    assert answers[-1]["places"] == [
        [p["static_id"], p["probability"]] for p in expected["most_likely_now"]
    ]
    assert answers[-1]["rooms"] == [[r["room"], r["probability"]] for r in expected["rooms"]]
    # The evidence age is the memory's own (agent/where.py), -1 where it gives none.
    age = expected["last_seen"].get("age_s")
    assert answers[-1]["seen"] and answers[-1]["age_s"] == (-1.0 if age is None else age)
    assert not asked["unknown"]["ok"] and "Unicorn" in asked["unknown"]["error"]
