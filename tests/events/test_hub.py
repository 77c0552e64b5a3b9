"""A projection hub restores its projections from one snapshot and folds each event once into
each; a snapshot of other members is not trusted."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.scene_graph import SceneGraphProjection
from objsearch.agent.state import AgentState
from objsearch.events import ProjectionError, fold, read_log
from objsearch.events.hub import Member, ProjectionHub, restore_hub
from objsearch.events.snapshot import save_snapshot, snapshot_path

V1_LOG = Path(__file__).parent / "fixtures" / "v1-log"
GRAPH: Member[SceneGraphProjection] = Member(
    "graph", SceneGraphProjection, SceneGraphProjection.from_snapshot
)
STATE: Member[AgentState] = Member("state", AgentState, AgentState.from_snapshot)


@pytest.fixture
def log(tmp_path: Path) -> Path:
    shutil.copytree(V1_LOG, tmp_path / "log")
    return tmp_path / "log"


def _tables(hub: ProjectionHub) -> tuple[Any, Any]:
    graph, state = hub["graph"], hub["state"]
    assert isinstance(graph, SceneGraphProjection) and isinstance(state, AgentState)
    return graph.as_table(), state.graph().as_table()


def test_one_snapshot_restores_every_member_as_a_full_fold_does(log: Path, tmp_path: Path) -> None:
    snaps = tmp_path / "snaps"
    events = list(read_log(log, store=STORE))
    expected = (
        fold(events, SceneGraphProjection()).as_table(),
        fold(events, AgentState()).graph().as_table(),
    )
    built, how = restore_hub(log, [GRAPH, STATE], snapshot_dir=snaps, store=STORE)
    assert how.from_snapshot_seq == 0 and built.applied == len(events)
    assert _tables(built) == expected
    save_snapshot(snaps, built, log=log, store=STORE)
    assert sorted(p.name for p in snaps.iterdir()) == ["projections.snapshot.json"]
    again, how = restore_hub(log, [GRAPH, STATE], snapshot_dir=snaps, store=STORE)
    assert how.rejected is None and how.from_snapshot_seq == len(events)
    assert again.applied == 0  # nothing read again
    assert _tables(again) == expected
    # A hub of other members does not trust it: rebuilt by one fold.
    other, how = restore_hub(log, [GRAPH], snapshot_dir=snaps, store=STORE)
    assert how.rejected is not None and "holds ['graph', 'state']" in how.rejected
    assert other.applied == len(events)
    assert snapshot_path(snaps, "projections").is_file()


def test_the_hub_refuses_a_gap_and_members_at_different_seqs(log: Path) -> None:
    events = list(read_log(log, store=STORE))
    hub = ProjectionHub({"graph": SceneGraphProjection()})
    hub.apply(events[0])
    with pytest.raises(ProjectionError, match="cannot apply seq 3"):
        hub.apply(events[2])
    ahead = fold(events[:1], SceneGraphProjection())
    with pytest.raises(ProjectionError, match="at one seq"):
        ProjectionHub({"a": ahead, "b": SceneGraphProjection()})
