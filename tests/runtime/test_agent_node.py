"""The robot process folds its log once (issue 22): one projection hub, restored from one
snapshot, gives each event once to each projection (the agent's state, its ``where`` memory),
which share one decode of each record; the live view reads the agent's state instead of
folding the log a third time."""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

import pytest

import objsearch.agent.catalogue as catalogue
from objsearch.agent.catalogue import STORE
from objsearch.agent.state import AgentState
from objsearch.agent.where import LiveMemory
from objsearch.events import Event, read_log
from objsearch.events.snapshot import snapshot_path
from objsearch.runtime.agent_node import SNAPSHOT_DIR, WHERE, AgentNode, GuardedLiveView
from objsearch.runtime.livesinks import McapSink

from .runtime_fixtures import Net
from .searches import TRIALS, client_config, in_process


@pytest.mark.parametrize("net", ["zenoh"], indirect=True)
def test_the_robot_process_folds_each_event_once(
    net: Net, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    log = tmp_path / "log"
    in_process(log, TRIALS[:2])  # a real log of two searches, no snapshot yet
    config = client_config(net)
    # Every fold of an agent's state in this process, counted: (which state, which seq).
    folds: Counter[tuple[int, int]] = Counter()
    apply = AgentState.apply

    def counted(self: AgentState, event: Event) -> None:
        folds[id(self), event.seq] += 1
        apply(self, event)

    monkeypatch.setattr(AgentState, "apply", counted)
    # Every record built from an event: (which record type, which event). The events are kept
    # alive so that no two share an id.
    decodes: Counter[tuple[str, int]] = Counter()
    seen: list[object] = []
    decode = catalogue._decode

    def counted_decode(event: Any, as_type: Any) -> Any:
        seen.append(event)
        decodes[(as_type or catalogue.LATEST[event.type]).__name__, id(event)] += 1
        return decode(event, as_type)

    monkeypatch.setattr(catalogue, "_decode", counted_decode)

    def start(name: str) -> AgentNode:
        return AgentNode(config, log, live=[McapSink(tmp_path / f"{name}.mcap")])

    node = start("first")
    try:
        hub = node.session.hub
        memory = hub[WHERE]
        assert isinstance(memory, LiveMemory)
        (view,) = hub.observers
        assert isinstance(view, GuardedLiveView)
        assert view.view.agent is node.session.state  # the view draws from the hub's state
        end = node.session.log.last_seq
        states = {id(node.session.state), id(memory.state)}
        # No snapshot: one fold of the whole log, and the run_started this start appended.
        assert hub.applied == end
        assert {s for s, _ in folds} == states
        assert sorted(folds) == sorted((s, q) for s in states for q in range(1, end + 1))
        assert set(folds.values()) == {1}
        # Each record decoded once, however many projections (and the view) read it.
        assert decodes and set(decodes.values()) == {1}
    finally:
        node.close()
    assert snapshot_path(log / SNAPSHOT_DIR, "projections").is_file()

    folds.clear()
    decodes.clear()
    node = start("second")
    try:
        hub = node.session.hub
        memory = hub[WHERE]
        assert isinstance(memory, LiveMemory)
        # From the hub's one snapshot: only what this start appended is folded, once into each.
        assert node.session.log.last_seq == end + 1
        assert hub.applied == 1
        states = {id(node.session.state), id(memory.state)}
        assert sorted(folds) == sorted((s, end + 1) for s in states)
        assert set(folds.values()) == {1}
        assert memory.state.last_seq == node.session.state.last_seq == end + 1
        # What this start appended carries the record it was appended from (b165632): at most
        # one decode, none here.
        assert set(decodes.values()) <= {1}
    finally:
        node.close()
    assert [e.type for e in read_log(log, store=STORE)][end:] == ["run_started"]
