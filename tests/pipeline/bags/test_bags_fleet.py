"""``objsearch ingest`` straight into the fleet lake (a Delta table, in a folder or a bucket):
the same runs as the per-run-folder lake, a session's merge in one transaction, ``--reingest``,
idempotent re-ingest, every bag accounted for, and concurrent ingests of one robot's bags."""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake, TableLakeError
from objsearch.pipeline.bags.identity import bag_identity
from objsearch.pipeline.bags.ingest import ingest
from objsearch.pipeline.bags.lake import FleetBagLake
from objsearch.pipeline.bags.ledger import BAG_TYPE, bag_records
from objsearch.pipeline.bags.session import converter_key
from objsearch.ros.topics import TopicMap

from .bag_fixtures import Recorded, content, fleet


def test_split_pieces_in_any_order_make_the_folder_lakes_run(
    pieces: list[Path], tmp_path: Path
) -> None:
    shuffled = pieces[:]
    random.Random(5).shuffle(shuffled)
    folder = tmp_path / "folder"
    ingest(shuffled, folder)
    lake = fleet(tmp_path / "fleet")
    results = ingest(shuffled, lake)
    assert [r.error for r in results] == [None] * len(pieces)
    assert content(lake) == content(folder)
    assert len(content(lake)[0]) == 1  # one session, one run: the merges were one each
    # Again: known, not read, nothing committed; the table gains no version.
    version = TableLake(lake, store=STORE).table().version()
    again = ingest(shuffled, lake)
    assert all(r.already and r.report is None for r in again)
    assert TableLake(lake, store=STORE).table().version() == version


def test_a_bag_with_nothing_in_it_is_accounted_for(tmp_path: Path) -> None:
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    empty = tmp_path / "empty.bag"
    with Writer(empty) as writer:
        writer.add_connection(
            "/chatter", "std_msgs/msg/String", typestore=get_typestore(Stores.ROS1_NOETIC)
        )
    lake = fleet(tmp_path / "fleet")
    [result] = ingest([empty], lake)
    assert result.error is None and result.committed == 0 and "nothing committed" in result.note
    table = TableLake(lake, store=STORE)
    assert table.runs() == []
    [(bag_id, record)] = bag_records(table).items()
    doc = json.loads(record)
    assert doc["run"] is None and doc["report"]["bag_id"] == bag_id
    assert {f.kind for f in table.data_files()} == {BAG_TYPE}
    [again] = ingest([empty], lake)  # read again , nothing to keep
    assert again.error is None and again.committed == 0
    assert list(bag_records(table)) == [bag_id] and table.runs() == []
    assert list(FleetBagLake(lake).known_pieces()) == [bag_id]


def _answers(lake: str, bags: list[Path], topic_map: TopicMap | None = None) -> dict[str, str]:
    """What ingest asks the fleet lake of these bags (its stamps), checked against what the
    lake's rows record (every bag's latest converter)."""
    key = converter_key(topic_map or TopicMap())
    ids = [bag_identity(b)[0] for b in bags]
    answers = FleetBagLake(lake).pieces_known(ids, key)
    assert answers is not None
    recorded = FleetBagLake(lake).known_pieces()
    assert answers == {i: key for i in ids if recorded.get(i) == key}
    return dict(answers)


def test_whether_a_bag_is_there_is_read_from_the_log_not_the_rows(
    ros1: Recorded, pieces: list[Path], tmp_path: Path
) -> None:
    lake = fleet(tmp_path / "fleet")
    assert _answers(lake, [ros1.bag, *pieces]) == {}
    ingest(pieces[1:], lake)  # a provisional run, then merged as each piece arrives
    key = converter_key(TopicMap())
    ids = [bag_identity(p)[0] for p in pieces]
    assert _answers(lake, pieces) == dict.fromkeys(ids[1:], key)
    ingest(pieces[:1], lake)  # the first piece: every piece is now in the session's run
    assert _answers(lake, pieces) == dict.fromkeys(ids, key)
    no_odom = TopicMap({t: r for t, r in TopicMap().topics.items() if t != "/odom"})
    ingest(pieces[:1], lake, topic_map=no_odom)  # read with another converter: re-stamped
    assert _answers(lake, pieces[:1], no_odom) == {ids[0]: converter_key(no_odom)}
    assert _answers(lake, pieces) == dict.fromkeys(ids[1:], key)
    # No row is read: with every data file gone, the answers stay (listing them cannot).
    table = TableLake(lake, store=STORE)
    for f in table.data_files():
        (Path(table.uri) / f.path).unlink()
    answers = FleetBagLake(lake).pieces_known(ids, key)
    assert answers == dict.fromkeys(ids[1:], key)
    # Listing reads the runs' records, which went with the files: a clear error naming them.
    with pytest.raises(TableLakeError, match="the records of its runs cannot be read"):
        FleetBagLake(lake).known_pieces()


def test_a_table_made_before_bags_were_stamped_is_asked_by_its_rows(
    ros1: Recorded, tmp_path: Path
) -> None:
    from deltalake import CommitProperties, Transaction, write_deltalake

    from objsearch.events.lake import TABLE_FORMAT
    from objsearch.events.lake.schema import table_schema
    from objsearch.events.lake.transactions import IDENTITY_INDEX_APP

    lake = TableLake(tmp_path / "fleet", store=STORE)
    write_deltalake(  # as TableLake.create made it before (no stamp index)
        lake.uri,
        table_schema(STORE).empty_table(),
        partition_by=["type"],
        description=TABLE_FORMAT,
        commit_properties=CommitProperties(app_transactions=[Transaction(IDENTITY_INDEX_APP, 1)]),
    )
    key = converter_key(TopicMap())
    bag_id = bag_identity(ros1.bag)[0]
    [first] = ingest([ros1.bag], str(lake.root))
    assert first.error is None and not first.already
    assert FleetBagLake(str(lake.root)).pieces_known([bag_id], key) is None
    assert FleetBagLake(str(lake.root)).known_pieces() == {bag_id: key}
    [again] = ingest([ros1.bag], str(lake.root))
    assert again.already and again.report is None


INGEST = """
import sys
from pathlib import Path
from objsearch.pipeline.bags.ingest import ingest
results = ingest([Path(p) for p in sys.argv[2:]], sys.argv[1])
assert all(r.error is None for r in results), [r.error for r in results]
"""


@pytest.mark.slow  # two processes ingesting: ~30 s on a shared machine
def test_two_ingests_of_one_robots_pieces_at_once_make_one_run(
    pieces: list[Path], tmp_path: Path
) -> None:
    # Each process commits its half of the pieces; merges race with merges. Each commit is
    # decided from one version of the table and carries the robot's bag transaction, so a
    # commit decided from a table another changed since fails and is decided again.
    lake = fleet(tmp_path / "fleet")
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", INGEST, lake, *map(str, pieces[w::2])], env={**os.environ}
        )
        for w in range(2)
    ]
    assert [p.wait(timeout=900) for p in procs] == [0, 0]
    ingest(pieces, tmp_path / "folder")
    assert content(lake) == content(tmp_path / "folder")


def test_the_cli_ingests_into_a_bucket(
    ros1: Recorded, bucket: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from objsearch.cli import main

    lake = bucket
    argv = ["ingest", str(ros1.bag), "--robot", "r1", "--no-progress", "--lake", lake]
    assert main(argv) == 0
    assert "committed" in capsys.readouterr().out
    assert main(argv) == 0
    assert "already in the lake" in capsys.readouterr().out
    ingest([ros1.bag], tmp_path / "local", robot="r1")
    assert content(lake) == content(tmp_path / "local")
    sql = "SELECT count(*) FROM pose_observed"
    assert main(["query", "--lake", lake, "--format", "csv", sql]) == 0
    [run] = TableLake(lake, store=STORE).runs()
    assert capsys.readouterr().out.splitlines() == ["count_star()", str(run.rows["pose_observed"])]
