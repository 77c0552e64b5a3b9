"""What every snapshot store passes (today one: the attested JSON file of
:mod:`objsearch.events.snapshot`; ``test_snapshot_contract.py`` runs it). :class:`SnapshotContract`
is the abstract test case: a snapshot taken mid-log plus the events after it restores what a full
fold gives, and restoring again starts at the end; a snapshot that is damaged, of another log, of
another code version, or whose state does not restore is not trusted: the projection is rebuilt
from the log, and the reason said. Why a backend rejects is its own text (:attr:`reasons`)."""

from __future__ import annotations

import shutil
from abc import ABC, abstractmethod
from pathlib import Path
from typing import Any, ClassVar

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.scene_graph import SceneGraphProjection
from objsearch.events import EventLog, fold, read_log
from objsearch.events.snapshot import Restored, Snapshottable

from ..lake_logs import V1_LOG

#: The log's length (events).
V1_EVENTS = 812


def full(log: Path) -> SceneGraphProjection:
    return fold(read_log(log, store=STORE), SceneGraphProjection())


class _Garbage:
    """A projection of the same name whose state the real one cannot read (a writer's bug)."""

    snapshot_name: ClassVar[str] = "scene_graph"
    snapshot_version: ClassVar[int] = SceneGraphProjection.snapshot_version
    last_seq = V1_EVENTS
    state = None

    def apply(self, event: object) -> None:
        raise AssertionError

    def to_snapshot(self) -> dict[str, Any]:
        return {"first_run": 3}


class SnapshotContract(ABC):
    #: Why a snapshot is not trusted, by spoil: "damaged", "other_log", "code_version", "state".
    reasons: ClassVar[dict[str, str]]

    @abstractmethod
    def save(self, snapshots: Path, projection: Snapshottable, log: Path) -> None: ...

    @abstractmethod
    def restore(self, log: Path, snapshots: Path) -> tuple[SceneGraphProjection, Restored]: ...

    @abstractmethod
    def damage(self, snapshots: Path) -> None:
        """Change a byte of the stored snapshot."""

    @pytest.fixture
    def log(self, tmp_path: Path) -> Path:
        shutil.copytree(V1_LOG, tmp_path / "log")
        return tmp_path / "log"

    def test_a_snapshot_mid_task_then_the_rest_equals_a_full_fold(
        self, log: Path, tmp_path: Path
    ) -> None:
        partial = fold(read_log(log, store=STORE), SceneGraphProjection(), until_seq=400)
        assert partial.experience  # mid-task: the experience pool is part of the state
        self.save(tmp_path / "snaps", partial, log)
        graph, how = self.restore(log, tmp_path / "snaps")
        assert how.from_snapshot_seq == 400 and how.rejected is None
        assert how.folded == V1_EVENTS - 400
        expected = full(log)
        assert graph.relations == expected.relations
        assert (graph.last_seq, graph.tasks_folded) == (expected.last_seq, expected.tasks_folded)
        again, how = self.restore(log, tmp_path / "snaps")  # the restore saved one at the end
        assert how.from_snapshot_seq == V1_EVENTS and how.folded == 0
        assert again.relations == expected.relations

    @pytest.mark.parametrize("spoil", ["damaged", "code_version", "other_log"])
    def test_a_snapshot_that_does_not_match_is_rebuilt(
        self, log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, spoil: str
    ) -> None:
        snaps = tmp_path / "snaps"
        self.save(
            snaps, fold(read_log(log, store=STORE), SceneGraphProjection(), until_seq=500), log
        )
        if spoil == "damaged":
            self.damage(snaps)
        elif spoil == "code_version":
            monkeypatch.setattr(SceneGraphProjection, "snapshot_version", 2)
        else:  # same stream, another history after seq 1
            shutil.rmtree(log)
            with EventLog.open(log, "robot", store=STORE) as writer:
                for i in range(600):
                    writer.append("search_failed", {"reason": "x"}, time_ns=i)
        graph, how = self.restore(log, snaps)
        assert how.from_snapshot_seq == 0 and self.reasons[spoil] in str(how.rejected)
        assert graph.relations == full(log).relations

    def test_an_attested_snapshot_whose_state_does_not_restore_is_rebuilt(
        self, log: Path, tmp_path: Path
    ) -> None:
        snaps = tmp_path / "snaps"
        self.save(snaps, _Garbage(), log)  # whole, attested, a state that does not restore
        graph, how = self.restore(log, snaps)
        assert how.from_snapshot_seq == 0 and self.reasons["state"] in str(how.rejected)
        assert graph.relations == full(log).relations
        again, how = self.restore(log, snaps)  # the rebuild saved a good one
        assert how.from_snapshot_seq == V1_EVENTS and how.rejected is None
        assert again.relations == graph.relations
