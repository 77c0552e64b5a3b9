"""Projections as they were at any point of a log."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

from objsearch.agent.catalogue import STORE
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.relations import RelationModel
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import AGENT_MODELS, RelationModels
from objsearch.events import Event, fold, read_log


def agent_state_at(
    log_dir: Path,
    seq: int | None = None,
    *,
    models: RelationModels = AGENT_MODELS,
    progress: Callable[[Iterable[Event]], Iterable[Event]] | None = None,
) -> AgentState:
    """What the agent knew right after ``seq`` (the whole log when None); ``models`` builds the
    relation models outside the agent a spec may name; ``progress`` wraps the events as they
    are folded (the CLI's progress line)."""
    if seq is not None and seq < 1:
        raise ObjsearchError(f"--until must be a sequence number ≥ 1, got {seq}")
    events = read_log(log_dir, to_seq=seq, store=STORE)
    state = fold(progress(events) if progress else events, AgentState(models=models), until_seq=seq)
    if seq is not None and state.last_seq < seq:
        raise ObjsearchError(f"log {log_dir} ends at seq {state.last_seq}; cannot show seq {seq}")
    return state


def scene_graph_at(
    log_dir: Path,
    seq: int | None = None,
    *,
    models: RelationModels = AGENT_MODELS,
    progress: Callable[[Iterable[Event]], Iterable[Event]] | None = None,
) -> RelationModel:
    """The relation model the run's spec names, folded up to and including ``seq``."""
    return agent_state_at(log_dir, seq, models=models, progress=progress).graph()
