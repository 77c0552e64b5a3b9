"""The bag lake contract (:mod:`.bag_lake_contract`) run against the fleet lake ingest writes to
(in a folder; ``test_bags_fleet.py`` ingests into a bucket)."""

from __future__ import annotations

from pathlib import Path

from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake

from .bag_fixtures import fleet
from .bag_lake_contract import BagLakeContract


class TestFleetBagLake(BagLakeContract):
    def make(self, root: Path) -> str:
        return fleet(root)

    def written(self, lake: str) -> object:
        return TableLake(lake, store=STORE).table().version()
