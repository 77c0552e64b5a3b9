"""Snapshots restore a projection fast, and are rebuilt whenever they no longer match."""

from __future__ import annotations

import json
import shutil
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any, ClassVar

import pytest

from objsearch.agent.catalogue import STORE
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
        log,
        SceneGraphProjection,
        SceneGraphProjection.from_snapshot,
        snapshot_dir=snaps,
        store=STORE,
    )


def full(log: Path) -> SceneGraphProjection:
    return fold(read_log(log, store=STORE), SceneGraphProjection())


def test_a_snapshot_mid_task_then_the_rest_equals_a_full_fold(log: Path, tmp_path: Path) -> None:
    partial = fold(read_log(log, store=STORE), SceneGraphProjection(), until_seq=400)
    assert partial.experience  # mid-task: the experience pool is part of the state
    save_snapshot(tmp_path / "snaps", partial, log=log, store=STORE)
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
        ("other_log", "not one the log's writer attested"),
    ],
)
def test_a_snapshot_that_does_not_match_is_rebuilt(
    log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, spoil: str, reason: str
) -> None:
    snaps = tmp_path / "snaps"
    save_snapshot(
        snaps,
        fold(read_log(log, store=STORE), SceneGraphProjection(), until_seq=500),
        log=log,
        store=STORE,
    )
    if spoil == "version":
        _corrupt_version(snapshot_path(snaps, "scene_graph"))
    elif spoil == "code_version":
        monkeypatch.setattr(SceneGraphProjection, "snapshot_version", 2)
    else:  # same stream, different history after seq 1
        shutil.rmtree(log)
        with EventLog.open(log, "robot", store=STORE) as writer:
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


def _resealed(path: Path, edit: Callable[[dict[str, Any]], None]) -> None:
    """Edit a snapshot's document and recompute its own CRC-32, as a careful hand would."""
    doc = json.loads(path.read_bytes())
    del doc["crc32"]
    edit(doc)
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"))
    path.write_text(text[:-1] + f',"crc32":"{zlib.crc32(text.encode()):08x}"}}\n')


def test_a_snapshot_edited_and_rechecksummed_is_not_believed(
    log: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    snaps = tmp_path / "snaps"
    save_snapshot(snaps, full(log), log=log, store=STORE)
    assert _restore(log, snaps)[1].rejected is None  # type: ignore[attr-defined]

    def bump(doc: dict[str, Any]) -> None:
        doc["state"]["tasks_folded"] += 1

    _resealed(snapshot_path(snaps, "scene_graph"), bump)
    caplog.clear()
    graph, how = _restore(log, snaps)
    assert how.from_snapshot_seq == 0 and "attested" in str(how.rejected)  # type: ignore[attr-defined]
    assert graph.tasks_folded == full(log).tasks_folded  # the log's fold, not the edit
    assert [r.levelname for r in caplog.records] == ["WARNING"]  # one line says so


class _Garbage:
    """A projection of the same name whose state the real one cannot read (a writer's bug)."""

    snapshot_name: ClassVar[str] = "scene_graph"
    snapshot_version: ClassVar[int] = SceneGraphProjection.snapshot_version
    last_seq = 812
    state = None

    def apply(self, event: object) -> None:
        raise AssertionError

    def to_snapshot(self) -> dict[str, Any]:
        return {"first_run": 3}


def test_an_attested_snapshot_whose_state_does_not_restore_is_rebuilt(
    log: Path, tmp_path: Path
) -> None:
    snaps = tmp_path / "snaps"
    save_snapshot(snaps, _Garbage(), log=log, store=STORE)  # valid CRC, attested, malformed state
    graph, how = _restore(log, snaps)
    assert how.from_snapshot_seq == 0 and "does not restore" in str(how.rejected)  # type: ignore[attr-defined]
    assert graph.relations == full(log).relations
    again, how = _restore(log, snaps)  # the rebuild saved a good one
    assert how.from_snapshot_seq == 812 and how.rejected is None  # type: ignore[attr-defined]
    assert again.relations == graph.relations
