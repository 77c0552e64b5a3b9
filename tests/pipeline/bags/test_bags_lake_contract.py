"""The bag lake contract (:mod:`.bag_lake_contract`) run against each lake ingest writes to."""

from __future__ import annotations

from pathlib import Path

from objsearch.agent.catalogue import STORE
from objsearch.events.lake_table import TableLake

from .bag_fixtures import fleet
from .bag_lake_contract import BagLakeContract


class TestFolderBagLake(BagLakeContract):
    def make(self, root: Path) -> str:
        return str(root)

    def written(self, lake: str) -> object:
        files = sorted(p for p in Path(lake).rglob("*") if p.is_file())
        return [(str(p), p.stat().st_mtime_ns) for p in files]


class TestFleetBagLake(BagLakeContract):
    def make(self, root: Path) -> str:
        return fleet(root)

    def written(self, lake: str) -> object:
        return TableLake(lake, store=STORE).table().version()
