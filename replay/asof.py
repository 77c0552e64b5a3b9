"""Projections as they were at any point of a log."""

from __future__ import annotations

from pathlib import Path

from objsearch.agent.errors import ObjsearchError
from objsearch.agent.scene_graph import SceneGraphProjection
from objsearch.events import fold, read_log


def scene_graph_at(log_dir: Path, seq: int | None = None) -> SceneGraphProjection:
    """Fold the log up to and including ``seq`` (the whole log when None)."""
    if seq is not None and seq < 1:
        raise ObjsearchError(f"--at must be a sequence number ≥ 1, got {seq}")
    graph = fold(read_log(log_dir, to_seq=seq), SceneGraphProjection(), until_seq=seq)
    if seq is not None and graph.last_seq < seq:
        raise ObjsearchError(f"log {log_dir} ends at seq {graph.last_seq}; cannot show seq {seq}")
    return graph
