"""Snapshots restore a projection fast, and are rebuilt whenever they no longer match."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from objsearch.agent.scene_graph import SceneGraphProjection
from objsearch.events import EventLog, fold, read_log
from objsearch.events.snapshot import restore, save_snapshot, snapshot_path

V1_LOG = Path(__file__).parent / "fixtures" / "v1-log"


@pytest.fixture
def log(tmp_path: Path) -> Path:
    shutil.copytree(V1_LOG, tmp_path / "log")
    return tmp_path / "log"


def _restore(log: Path, snaps: Path) -> tuple[SceneGraphProjection, object]:
    return restore(
        log, SceneGraphProjection, SceneGraphProjection.from_snapshot, snapshot_dir=snaps
    )


def full(log: Path) -> SceneGraphProjection:
    return fold(read_log(log), SceneGraphProjection())


def test_a_snapshot_mid_task_then_the_rest_equals_a_full_fold(log: Path, tmp_path: Path) -> None:
    partial = fold(read_log(log), SceneGraphProjection(), until_seq=400)
    assert partial.experience  # mid-task: the experience pool is part of the state
    save_snapshot(tmp_path / "snaps", partial, log_dir=log)
    graph, how = _restore(log, tmp_path / "snaps")
    assert how.from_snapshot_seq == 400 and how.rejected is None  # type: ignore[attr-defined]
    assert how.folded == 812 - 400  # type: ignore[attr-defined]
    expected = full(log)
    assert graph.relations == expected.relations
    assert (graph.last_seq, graph.tasks_folded) == (expected.last_seq, expected.tasks_folded)
    again, how = _restore(log, tmp_path / "snaps")  # the restore saved a snapshot at the end
    assert how.from_snapshot_seq == 812 and how.folded == 0  # type: ignore[attr-defined]
    assert again.relations == expected.relations


def _corrupt_version(path: Path) -> None:
    text = path.read_text()
    path.write_text(text.replace('"projection_version":1', '"projection_version":0'))


@pytest.mark.parametrize(
    ("spoil", "reason"),
    [
        ("version", "checksum mismatch"),
        ("code_version", "projection version 1 ≠ the code's 2"),
        ("other_log", "is not the one the snapshot saw"),
    ],
)
def test_a_snapshot_that_does_not_match_is_rebuilt(
    log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, spoil: str, reason: str
) -> None:
    snaps = tmp_path / "snaps"
    save_snapshot(snaps, fold(read_log(log), SceneGraphProjection(), until_seq=500), log_dir=log)
    if spoil == "version":
        _corrupt_version(snapshot_path(snaps, "scene_graph"))
    elif spoil == "code_version":
        monkeypatch.setattr(SceneGraphProjection, "snapshot_version", 2)
    else:  # same stream, different history after seq 1
        shutil.rmtree(log)
        with EventLog.open(log, "robot") as writer:
            for i in range(600):
                writer.append(
                    "search_failed",
                    {"reason": "x"},
                    time_ns=i,
                )
        assert json.loads(snapshot_path(snaps, "scene_graph").read_text())["seq"] == 500
    graph, how = _restore(log, snaps)
    assert how.from_snapshot_seq == 0 and reason in str(how.rejected)  # type: ignore[attr-defined]
    assert graph.relations == full(log).relations
