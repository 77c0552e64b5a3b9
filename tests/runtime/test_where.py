"""``where`` asked of a running agent over a real transport: the answer is the one ``objsearch
where --log`` gives for the same log, a malformed question is answered with an error naming its
field, the agent carries on answering afterwards, and after a restart (from its snapshot)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from objsearch.cli import main
from objsearch.events.snapshot import snapshot_path
from objsearch.runtime.agent_node import SNAPSHOT_DIR
from objsearch.runtime.client import AgentClient
from objsearch.runtime.node import Requester
from objsearch.runtime.requests import check_where_result

from .runtime_fixtures import STARTUP_S, Net, objsearch, stop
from .searches import client_config, robot_config


@pytest.mark.parametrize("net", ["zenoh"], indirect=True)
def test_the_agent_answers_where_from_its_live_memory(
    net: Net, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "log"
    robot = objsearch("robot", "sim", *net.args, log=tmp_path / "robot.txt")
    alone = robot_config(tmp_path, "")
    agent = objsearch(
        "agent", "run", *net.args, *alone, "--log", str(log), log=tmp_path / "agent.txt"
    )
    try:
        config = client_config(net)
        with AgentClient(config) as client:
            reset = client.reset_sim(1, "kitchen-1", timeout_s=STARTUP_S)
            found = client.find(
                "Apple",
                start="kitchen-1",
                scene=1,
                timeout_s=STARTUP_S,
                not_before_ns=reset["stamp_ns"],
            )
            assert found["ok"] and found["success"], found
            live = client.where("Apple", timeout_s=20)
            assert live["ok"], live
            assert live["answer"]["tasks"] == 1
            assert live["answer"]["last_seen"] is not None
            unknown = client.where("Unicorn", timeout_s=20)
            assert not unknown["ok"] and "field 'target'" in unknown["error"]
            raw = Requester(
                client.node,
                config.topics.where,
                config.topics.where_result,
                config.qos.requests,
                check_where_result,
            )
            malformed = raw.call({"target": 7}, timeout_s=20)
            assert not malformed["ok"] and "where request: field 'target'" in malformed["error"]
        # The command-line client, after the malformed question: the agent is still answering.
        assert (
            main(
                [
                    "agent",
                    "where",
                    "Apple",
                    *net.args,
                    "--format",
                    "json",
                    "--timeout",
                    str(STARTUP_S),
                ]
            )
            == 0
        )
        again = json.loads(capsys.readouterr().out)
        assert again["answer"] == live["answer"]
        assert agent.poll() is None
    finally:
        assert stop(agent) == 0
        stop(robot)
    assert main(["where", "Apple", str(log), "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out) == live["answer"]
    # A restart restores the memory from the snapshot written at shutdown (the process's one
    # projection hub's: the agent's state and its memory), and answers the same.
    assert snapshot_path(log / SNAPSHOT_DIR, "projections").is_file()
    agent = objsearch(
        "agent", "run", *net.args, *alone, "--log", str(log), log=tmp_path / "agent2.txt"
    )
    try:
        assert (
            main(
                [
                    "agent",
                    "where",
                    "Apple",
                    *net.args,
                    "--format",
                    "json",
                    "--timeout",
                    str(STARTUP_S),
                ]
            )
            == 0
        )
        assert json.loads(capsys.readouterr().out)["answer"] == live["answer"]
    finally:
        assert stop(agent) == 0
