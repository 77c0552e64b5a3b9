"""Every real bag in ../shared/data/bags ingests: unknown topics and custom types are reported."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from objsearch.pipeline.bags.ingest import ingest
from objsearch.pipeline.bags.read import read_bag
from objsearch.ros.topics import TopicMap


def _bags(root: Path) -> list[Path]:
    return sorted(root.rglob("*.bag")) + sorted(p.parent for p in root.rglob("metadata.yaml"))


def test_every_shared_bag_ingests(shared_bags: Path, tmp_path: Path) -> None:
    bags = _bags(shared_bags)
    assert len(bags) == 11  # 7 ROS 1 files, 4 ROS 2 directories
    results = ingest(bags, tmp_path / "lake", workers=2)
    assert [r.error for r in results] == [None] * len(bags)
    for r in results:
        assert r.report is not None and not r.report.losses
        # Nothing in these bags is silently dropped: each topic is converted, counted or skipped.
        assert r.report.topics or r.report.skipped


def test_custom_and_unknown_types_are_named(shared_bags: Path) -> None:
    report = read_bag(shared_bags / "rosbag2" / "cdr_test_mcap").report
    reasons = {s.topic: s.reason for s in report.skipped}
    assert "custom type test_msgs/msg/BasicTypes" in reasons["/test_topic"]
    # Counted from the index once: a bag with nothing to convert is not also iterated.
    assert {s.topic: s.messages for s in report.skipped} == {"/array_topic": 4, "/test_topic": 3}
    assert report.events == 0
    stemo = read_bag(shared_bags / "stemo" / "vibe_0322_run1_lz4.bag").report
    info = {s.topic: s for s in stemo.skipped}["/vibe_ros/left/camera_info"]
    assert info.messages == 838 and "would be read as camera_info" in info.reason


def test_ros1_tf_bag_counts_messages_and_time_range(shared_bags: Path) -> None:
    for name in ("example.bag", "example-lz4.bag", "example-bz2.bag"):
        report = read_bag(shared_bags / "rosbag.js" / name).report
        tf = [t for t in report.topics if t.topic == "/tf"]
        assert sum(t.messages for t in tf) == 2688 and tf[0].msgtype == "tf/msg/tfMessage"
        assert report.start_ns is not None and report.end_ns is not None
        assert 21 < (report.end_ns - report.start_ns) / 1e9 < 22


def test_a_topic_map_turns_their_odometry_into_a_pose_track(
    shared_bags: Path, tmp_path: Path
) -> None:
    config = tmp_path / "topics.toml"
    config.write_text('[topics]\n"/base_pose_ground_truth" = "odometry"\n', encoding="utf-8")
    contents = read_bag(shared_bags / "embag" / "test.bag", TopicMap.load(config))
    poses = [e for e in contents.events if e.type == "pose_observed"]
    assert len(poses) == 5  # PROVENANCE: nav_msgs/Odometry ×5
    assert {e.payload["topic"] for e in poses} == {"/base_pose_ground_truth"}


@pytest.mark.parametrize("name", ["talker_sqlite3", "talker_mcap"])
def test_ros2_talker_bags(shared_bags: Path, name: str) -> None:
    report = read_bag(shared_bags / "rosbag2" / name).report
    skipped = {s.topic: s for s in report.skipped}
    assert skipped["/topic"].messages == 10
    assert skipped["/topic"].msgtype == "std_msgs/msg/String"


def test_a_real_bag_reaches_the_lake(
    shared_bags: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from objsearch.agent.catalogue import STORE
    from objsearch.cli import main
    from objsearch.events.lake import TableLake

    config = tmp_path / "topics.toml"
    config.write_text('[topics]\n"/base_pose_ground_truth" = "odometry"\n', encoding="utf-8")
    bag = str(shared_bags / "embag" / "test.bag")
    lake = tmp_path / "lake"
    argv = ["ingest", bag, "--topics", str(config), "--robot", "r1", "--no-progress"]
    # The run, its events and its ingest report; twice is a no-op.
    for _ in range(2):
        assert main([*argv, "--lake", str(lake)]) == 0
    runs = TableLake(lake, store=STORE).runs()
    assert [(r.robot, dict(r.rows)) for r in runs] == [("r1", {"pose_observed": 5})]
    report = json.loads(runs[0].attachments["_ingest.json"])
    assert report and runs[0].source.startswith("bag:")
    capsys.readouterr()
    sql = "SELECT run, count(*) AS n FROM pose_observed GROUP BY 1"
    assert main(["query", "--lake", str(lake), "--format", "csv", sql]) == 0
    assert capsys.readouterr().out.splitlines() == ["run,n", f"{runs[0].run},5"]
