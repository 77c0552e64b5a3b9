"""The lake contract (:mod:`.lake_contract`) run against each backend of the fleet lake: its
Delta table in a folder, and the same table in a bucket of moto's S3 server."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake, TableRun, add_log

from .lake_contract import LakeContract, damage_file


class TestTableLake(LakeContract[TableLake, TableRun]):
    def open(self, root: Path | str) -> TableLake:
        return TableLake(root, store=STORE)

    def add(
        self, log: Path, lake: TableLake, *, robot: str, run: str | None = None, **kwargs: Any
    ) -> TableRun:
        return add_log(log, lake, robot=robot, run=run, **kwargs)

    def remove(self, lake: TableLake, info: TableRun) -> None:
        assert lake.remove_run(info.robot, info.run)

    def written(self, lake: TableLake) -> object:
        return lake.table().version()

    def damage(self, lake: TableLake, info: TableRun, event_type: str, how: str) -> str:
        [victim] = [f for f in lake.data_files() if f.kind == event_type and info.commit in f.path]
        damage_file(Path(lake.uri) / victim.path, how)
        return victim.path

    def reported(self, lake: TableLake) -> list[str]:
        return [f"{name}: {why}" for name, why in lake.verify().damaged]

    def run_names(self, lake: TableLake) -> list[str]:
        return [r.run for r in lake.runs()] if lake.exists() else []


class TestTableLakeOnS3(TestTableLake):
    no_file_damage = (
        "a bucket serves an object whole or not at all: the object store checks what it "
        "serves (TableLake.scan), so no file of it is cut or lost one at a time here"
    )
    # Each case costs seconds on moto's server; the bucket runs the same TableLake code as
    # TestTableLake, so it runs the two cases that cross the storage in every way: the same run
    # again (found through the table's log, nothing written), and another content refused, then
    # replaced (an overwrite on the bucket) and read back equal to its log.
    cases = frozenset(
        {
            "test_adding_the_same_log_again_is_a_no_op",
            "test_other_content_under_a_runs_name_needs_replace",
        }
    )
    narrowed = "the same TableLake code as TestTableLake; on the bucket only the storage cases run"

    @pytest.fixture
    def root(self, bucket: str) -> Path | str:
        return bucket
