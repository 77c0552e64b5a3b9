"""The bags' ledger: the ingest record of each bag that made no run (or whose events the lake
held already), kept in the fleet lake beside the runs, so the lake accounts for every bag it
was given. A record is one row of type :data:`BAG_TYPE` outside any run
(:meth:`~objsearch.events.lake.TableLake.commit_outside_runs`); the latest row of a bag id is
its record. The lake keeps the rows; what they mean is the bag pipeline's."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Final

from objsearch.events.lake import TableLake, TableRun

#: The ``type`` partition of the bags' ingest records.
BAG_TYPE: Final = "_bag"


def record_bag(
    lake: TableLake, bag_id: str, robot: str | None, doc: str, stamps: Sequence[str] = ()
) -> None:
    """Keep a bag's ingest record ``doc`` (JSON text) that belongs to no run's commit, in a
    transaction of its own (with ``stamps`` as
    :meth:`~objsearch.events.lake.TableLake.commit_as_read` sets them)."""
    info = TableRun(
        robot=robot or "",
        date="1970-01-01",
        run=f"_bag:{bag_id}",  # no run is named so (a run name starts with a letter)
        commit="",  # the lake's, when it commits
        rows={},
        digest="",
        source=f"bag:{bag_id}",
        identity={"bag_id": bag_id},
        attachments={"record": doc},
    )
    lake.commit_outside_runs(BAG_TYPE, info, stamps=stamps, what=f"bag {bag_id[:16]}")


def bag_records(lake: TableLake, table: Any | None = None) -> dict[str, str]:
    """Bag id → its latest :func:`record_bag` record."""
    found: dict[str, tuple[str, str]] = {}
    for info in lake.rows_outside_runs(BAG_TYPE, table):
        bag_id = info.identity["bag_id"]
        doc = info.attachments["record"]
        if bag_id not in found or found[bag_id][0] < info.commit:
            found[bag_id] = (info.commit, doc)
    return {k: v for k, (_, v) in sorted(found.items())}


class BagLedger:
    """The ledger of one fleet lake, as the migration of a per-run-folder lake copies its
    ``_bags/`` into it (:class:`objsearch.events.lake.folder_v1.BagLedger`)."""

    def __init__(self, lake: TableLake) -> None:
        self.lake = lake

    def records(self) -> dict[str, str]:
        return bag_records(self.lake)

    def record(self, bag_id: str, robot: str | None, doc: str) -> None:
        record_bag(self.lake, bag_id, robot, doc)
