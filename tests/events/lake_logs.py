"""Small event logs the lake tests commit (shared helpers, not tests)."""

from __future__ import annotations

from pathlib import Path

from objsearch.agent.catalogue import STORE
from objsearch.events import EventLog

from .payloads import EXAMPLES, OLD_EXAMPLES

#: A log written by format-1 code (old event versions, plain CRCs).
V1_LOG = Path(__file__).parent / "fixtures" / "v1-log"


def small_log(directory: Path, *, stream: str = "run-a", n: int = 3) -> Path:
    """Every event type once, an old detection version, then ``n`` failures."""
    with EventLog.open(
        directory, stream, wall_clock=lambda: 1_700_000_000_000_000_000, store=STORE
    ) as log:
        for i, (event_type, payload) in enumerate(EXAMPLES.items()):
            log.append(event_type, payload, time_ns=i, task_id="t1")
        log.append("detection", OLD_EXAMPLES["detection", 1], time_ns=99, version=1)
        for i in range(n):
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=100 + i)
    return directory


def two_type_log(directory: Path) -> Path:
    """Two event types: every kind of step of a commit, few files (each kill costs a commit)."""
    with EventLog.open(
        directory, "run-a", wall_clock=lambda: 1_700_000_000_000_000_000, store=STORE
    ) as log:
        log.append("task_started", EXAMPLES["task_started"], time_ns=1, task_id="t1")
        for i in range(3):
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=100 + i)
    return directory
