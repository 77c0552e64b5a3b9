"""Searches the runtime tests run over real transports and in process (shared helpers)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from objsearch.agent.session import Session, load_context
from objsearch.agent.strategies import DEFAULT_STRATEGY, RunSpec
from objsearch.cli import build_parser
from objsearch.cli_runtime import runtime_config
from objsearch.runtime.client import AgentClient
from objsearch.runtime.config import RuntimeConfig
from objsearch.sim.placements import Schedule
from objsearch.sim.world import SimClock, SimWorld

from .runtime_fixtures import STARTUP_S, Net

# Scene 1 of Table II, in the long-term runner's order (scene → target → start), cut short for CI.
TRIALS = [(1, "Apple", "kitchen-1"), (1, "Apple", "bedroom-1"), (1, "Cup", "living-1")]


def client_config(net: Net) -> RuntimeConfig:
    return runtime_config(build_parser().parse_args(["agent", "find", "x", *net.args]))


def in_process(
    log_dir: Path,
    trials: list[tuple[int, str, str]] = TRIALS,
    strategy: str = DEFAULT_STRATEGY,
) -> list[dict[str, Any]]:
    """The same searches by the in-process simulator: what the processes must decide (with
    ``agent run``'s default strategy unless told)."""
    ctx = load_context("paper")
    schedule = Schedule.load(ctx.home, "table2")
    session = Session.start(ctx, log_dir, RunSpec.for_home(ctx.home, strategy))
    out = []
    try:
        for scene, target, start in trials:
            world = SimWorld(
                ctx.home,
                ctx.navmap,
                schedule.scenes[scene],
                ctx.home.start(start),
                clock=SimClock(),
            )
            r = session.search(world, target, start, scene=scene)
            out.append(
                {
                    "success": r.success,
                    "path_length": r.path_length,
                    "found": r.found_instance,
                    "plans": [[room, list(order)] for room, order in r.plans],
                }
            )
    finally:
        session.close()
    return out


ACTION = '[navigation]\ninterface = "navigate_to_pose"\n'
TF = '[pose]\nsource = "tf"\n'


#: ``[timeouts] claim_s`` of the agents these tests start: each runs alone on a domain (or zenoh
#: router) of its test, so the 5 s an agent waits at start for another of its robot is waited
#: for nothing (about 5 s per start, ~100 s over the suite). test_oneagent.py tests the claim.
ALONE = "claim_s = 0.1\n"


def robot_config(tmp_path: Path, text: str) -> list[str]:
    """robot.toml with ``text``, for the agent and the stand-in robot alike (the robot has no
    claim); the agent's claim wait is :data:`ALONE` unless ``text`` sets one."""
    if "claim_s" not in text:
        text = text.replace("[timeouts]\n", "[timeouts]\n" + ALONE, 1)
        if ALONE not in text:
            text += "[timeouts]\n" + ALONE
    path = tmp_path / "robot.toml"
    path.write_text(text)
    return ["--config", str(path)]


def find_after_reset(client: AgentClient, scene: int, target: str, start: str) -> dict[str, Any]:
    reset = client.reset_sim(scene, start, timeout_s=STARTUP_S)
    assert reset["ok"]
    return client.find(
        target, start=start, scene=scene, timeout_s=STARTUP_S, not_before_ns=reset["stamp_ns"]
    )


def decisions(r: dict[str, Any]) -> dict[str, Any]:
    return {k: r[k] for k in ("success", "path_length", "found", "plans")}
