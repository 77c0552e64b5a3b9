"""What the robot process folds per event: its projection hub against the three separate folds
it had before (issue 22), over the same events, in the same run.

    python benchmarks/projection_hub.py LOG [--reps 5]

The baseline is what ``agent run --live`` kept until the hub: three ``AgentState`` folds of every
event (the agent's own, its ``where`` memory with the memory model, the live view's own copy of
the agent's). The hub folds the agent's and the memory's, once each; the live view reads the
agent's. Printed for each: ``AgentState.apply`` calls and decodes (records built from an
event: ``agent/catalogue.py``'s ``_decode``) per event, and the CPU time of the fold (median of ``--reps``).
The events are read once, before any fold is timed.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import objsearch.agent.catalogue as catalogue
from objsearch.agent.catalogue import STORE
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import ROUTINE_BELIEF
from objsearch.agent.where import LiveMemory
from objsearch.events import Event, read_log
from objsearch.events.hub import ProjectionHub
from objsearch.events.projection import EventObserver

Build = Callable[[], Sequence[EventObserver]]


def separate() -> Sequence[EventObserver]:
    return [AgentState(), AgentState(counterfactual=ROUTINE_BELIEF), AgentState()]


def hub() -> Sequence[EventObserver]:
    memory = LiveMemory(AgentState(counterfactual=ROUTINE_BELIEF), None)  # type: ignore[arg-type]
    return [ProjectionHub({"agent": AgentState(), "where": memory})]


def counts(events: Sequence[Event], build: Build) -> tuple[float, float]:
    """``AgentState.apply`` calls and decodes per event."""
    applies = 0
    decodes: Counter[str] = Counter()
    apply, decode = AgentState.apply, catalogue._decode

    def counted_apply(self: AgentState, event: Any) -> None:
        nonlocal applies
        applies += 1
        apply(self, event)

    def counted_decode(event: Any, as_type: Any) -> Any:
        decodes[event.type] += 1
        return decode(event, as_type)

    AgentState.apply = counted_apply  # type: ignore[method-assign]
    catalogue._decode = counted_decode
    try:
        observers = build()
        for event in events:
            for observer in observers:
                observer.apply(event)
    finally:
        AgentState.apply = apply  # type: ignore[method-assign]
        catalogue._decode = decode
    return applies / len(events), sum(decodes.values()) / len(events)


def cpu(events: Sequence[Event], build: Build) -> float:
    observers = build()
    start = time.process_time()
    for event in events:
        for observer in observers:
            observer.apply(event)
    return time.process_time() - start


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", type=Path, help="an agent's event log folder")
    parser.add_argument("--reps", type=int, default=5)
    args = parser.parse_args(argv)
    events = list(read_log(args.log, store=STORE))
    print(f"{len(events)} events of {args.log}")
    base = None
    for name, build in (("three separate folds (before)", separate), ("projection hub", hub)):
        # Fresh events each time: a read payload caches its decoded dict once looked at.
        per_apply, per_decode = counts(list(read_log(args.log, store=STORE)), build)
        secs = statistics.median(
            cpu(list(read_log(args.log, store=STORE)), build) for _ in range(args.reps)
        )
        base = base or secs
        print(
            f"{name:32} AgentState.apply {per_apply:.2f}/event, decodes {per_decode:.2f}/event, "
            f"fold {secs:.4f} CPU-s (median of {args.reps}; {secs / base:.2f} x before)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
