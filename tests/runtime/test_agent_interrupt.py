"""Ctrl-C stops ``agent run`` while it restores its state from a long log: exit 130 (the CLI's
code for an interrupted command), the log whole and unlocked."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

from objsearch.agent.catalogue import STORE
from objsearch.events import EventLog, read_log

from .runtime_fixtures import STARTUP_S, next_domain

#: Events in the log: a restore of this many takes seconds, far longer than a signal's delivery.
EVENTS = 60_000
RESTORING = b"restoring the agent's state from log"


def _long_log(directory: Path) -> Path:
    with EventLog.open(directory, "robot", store=STORE) as log:
        for start in range(0, EVENTS, 1000):
            with log.batch():
                for i in range(start, start + 1000):
                    log.append("search_failed", {"reason": f"r{i}"}, time_ns=i)
    return directory


def _ignore_sigint() -> None:
    # As a shell script's background job starts: SIGINT ignored. Python then installs no
    # handler of its own, so only the agent's own handler can make Ctrl-C stop it.
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def test_sigint_while_restoring_stops_the_agent(tmp_path: Path) -> None:
    log_dir = _long_log(tmp_path / "log")
    domain = ["--transport", "dds", "--domain-id", str(next_domain())]
    agent = subprocess.Popen(
        [sys.executable, "-m", "objsearch.cli", "agent", "run", *domain, "--log", str(log_dir)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        preexec_fn=_ignore_sigint,
    )
    assert agent.stdout is not None
    said: list[bytes] = []
    try:
        # The signal goes as soon as the agent says the restore began (not after a guessed
        # delay): the restore of EVENTS events is still under way when it arrives.
        for line in agent.stdout:
            said.append(line)
            if RESTORING in line:
                break
        else:
            raise AssertionError(f"the agent exited before restoring: {b''.join(said)!r}")
        agent.send_signal(signal.SIGINT)
        rc = agent.wait(STARTUP_S)  # before the fix: ignored, it restores and then serves
        said.extend(agent.stdout)
    finally:
        if agent.poll() is None:
            agent.kill()
            agent.wait()
        agent.stdout.close()
    output = b"".join(said).decode(errors="replace")
    assert rc == 130, output
    assert "agent up" not in output and "serving searches" not in output, output
    assert "Traceback" not in output, output
    # Nothing lost: every event is still there, and the log opens again (its lock was released).
    assert sum(1 for _ in read_log(log_dir, store=STORE)) == EVENTS
    with EventLog.open(log_dir, "robot", store=STORE) as log:
        assert log.last_seq == EVENTS
