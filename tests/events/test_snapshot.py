"""The JSON snapshot file beyond the snapshot contract (``tests/events/contract/``): a snapshot
edited by hand and re-checksummed is still not believed."""

from __future__ import annotations

import json
import shutil
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.scene_graph import SceneGraphProjection
from objsearch.events import fold, read_log
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
