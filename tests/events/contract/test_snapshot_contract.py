"""The snapshot contract (:mod:`.snapshot_contract`) run against the attested JSON snapshot file."""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

from objsearch.agent.catalogue import STORE
from objsearch.agent.scene_graph import SceneGraphProjection
from objsearch.events.snapshot import Restored, Snapshottable, restore, save_snapshot, snapshot_path

from .snapshot_contract import SnapshotContract


class TestJsonSnapshots(SnapshotContract):
    reasons: ClassVar[dict[str, str]] = {
        "damaged": "checksum mismatch",
        "code_version": "projection version 1 ≠ the code's 2",
        "other_log": "not one the log's writer attested",
        "state": "does not restore",
    }

    def save(self, snapshots: Path, projection: Snapshottable, log: Path) -> None:
        save_snapshot(snapshots, projection, log=log, store=STORE)

    def restore(self, log: Path, snapshots: Path) -> tuple[SceneGraphProjection, Restored]:
        return restore(
            log,
            SceneGraphProjection,
            SceneGraphProjection.from_snapshot,
            snapshot_dir=snapshots,
            store=STORE,
        )

    def damage(self, snapshots: Path) -> None:
        path = snapshot_path(snapshots, "scene_graph")
        path.write_text(
            path.read_text().replace('"projection_version":1', '"projection_version":0')
        )
