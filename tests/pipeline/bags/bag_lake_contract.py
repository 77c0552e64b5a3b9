"""What ingest does with the lake that keeps the runs: the fleet lake's Delta table
(:class:`FleetBagLake`). :class:`BagLakeContract` is the abstract test case, one subclass a
backend (``test_bags_lake_contract.py``); the lake itself has its contract in
``tests/events/contract/``."""

from __future__ import annotations

from abc import ABC, abstractmethod
from pathlib import Path

from objsearch.pipeline.bags.ingest import ingest
from objsearch.ros.topics import TopicMap

from .bag_fixtures import Recorded, content


class BagLakeContract(ABC):
    @abstractmethod
    def make(self, root: Path) -> str:
        """An empty lake of this kind at ``root``, as ingest is given it."""

    @abstractmethod
    def written(self, lake: str) -> object:
        """Something that changes whenever the lake is written to."""

    def test_ingesting_a_bag_again_is_a_no_op(self, ros1: Recorded, tmp_path: Path) -> None:
        lake = self.make(tmp_path / "lake")
        first = ingest([ros1.bag, ros1.bag], lake)  # the same bag twice: once
        assert len(first) == 1 and first[0].committed > 0 and first[0].error is None
        before = self.written(lake)
        [again] = ingest([ros1.bag], lake)
        assert again.already and again.committed == 0 and again.report is None
        assert again.error is None
        assert self.written(lake) == before  # known, not read, nothing written

    def test_a_changed_topic_map_reingests_replacing_the_bags_rows(
        self, ros1: Recorded, tmp_path: Path
    ) -> None:
        lake = self.make(tmp_path / "lake")
        [first] = ingest([ros1.bag], lake)
        assert first.report is not None
        no_odom = TopicMap({t: r for t, r in TopicMap().topics.items() if t != "/odom"})
        [again] = ingest([ros1.bag], lake, topic_map=no_odom)
        assert not again.already and again.report is not None
        # Poses now come from /tf alone, and the run holds them once, not twice.
        [(_, _, rows, _)] = content(lake)[0]
        assert rows["pose_observed"] == again.report.event_types["pose_observed"]
        # The lake is as a first ingest with that converter leaves one.
        fresh = self.make(tmp_path / "fresh")
        ingest([ros1.bag], fresh, topic_map=no_odom)
        assert content(lake) == content(fresh)
        [same] = ingest([ros1.bag], lake, topic_map=no_odom)
        assert same.already
        [forced] = ingest([ros1.bag], lake, topic_map=no_odom, reingest=True)
        assert not forced.already and forced.error is None
        assert content(lake) == content(fresh)
