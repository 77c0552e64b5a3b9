"""A flipped bit in an odometry message of a bag without checksums (rosbag2 SQLite, ROS 1): what
ingest can tell from the data, and what it notes (docs/pipeline.md, "Damaged bags")."""

from __future__ import annotations

import shutil
import sqlite3
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from rosbags.highlevel import AnyReader

from objsearch.pipeline.bags import fastdecode
from objsearch.pipeline.bags.formats import BagFormat
from objsearch.pipeline.bags.ingest import ingest
from objsearch.pipeline.bags.read import read_bag
from objsearch.ros.types import Distro, typestore

from .bag_fixtures import Recorded, record_run

TWICE = Path(__file__).parent / "fixtures" / "twice"


@pytest.fixture(scope="module")
def sqlite_bag(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    return record_run(tmp_path_factory.mktemp("bag-sqlite"), BagFormat.ROS2_SQLITE3)


def _flip_odometry(
    recorded: Recorded,
    dest: Path,
    pick: Callable[[Any], bool],
    where: Callable[[fastdecode.Layout], int],
    bit: int,
) -> Path:
    """A copy of the bag with one bit of one odometry message flipped in its database: the
    middle one of those ``pick`` takes (the deserialised pose), at byte ``where(layout)`` +
    bit // 8."""
    bag = dest / "run"
    shutil.copytree(recorded.bag, bag)
    [db] = bag.glob("*.db3")
    con = sqlite3.connect(db)
    try:
        [(topic_id,)] = con.execute("SELECT id FROM topics WHERE name = '/odom'")
        rows = con.execute(
            "SELECT id, data FROM messages WHERE topic_id = ? ORDER BY id", (topic_id,)
        ).fetchall()
        store = typestore(Distro.ROS2)
        chosen = [
            (i, bytes(d))
            for i, d in rows
            if pick(_odometry(store.deserialize_cdr(bytes(d), "nav_msgs/msg/Odometry")))
        ]
        row_id, raw = chosen[len(chosen) // 2]
        layout = fastdecode.odometry_layout_cdr(raw)
        assert layout is not None
        data = bytearray(raw)
        data[where(layout) + bit // 8] ^= 1 << (bit % 8)
        con.execute("UPDATE messages SET data = ? WHERE id = ?", (bytes(data), row_id))
        con.commit()
    finally:
        con.close()
    return bag


def _odometry(msg: Any) -> Any:
    """A deserialised nav_msgs/Odometry's pose (rosbags types it as ``object``)."""
    return msg.pose.pose


def _notes(bag: Path) -> list[str]:
    return [n for n in read_bag(bag).report.notes if "/odom" in n]


def test_the_intact_bag_has_no_such_note(sqlite_bag: Recorded) -> None:
    assert _notes(sqlite_bag.bag) == []


def test_a_quaternion_flip_the_rotation_check_lets_through_is_noted(
    sqlite_bag: Recorded, tmp_path: Path
) -> None:
    # qz's mantissa bit 30: |norm - 1| ~ 1e-7, inside the check's 1e-3, far outside the 1e-16
    # the topic's other quaternions hold.
    bag = _flip_odometry(
        sqlite_bag,
        tmp_path,
        lambda pose: abs(pose.orientation.z) > 0.3,
        lambda lay: lay.poses[0] + 40,
        30,
    )
    assert read_bag(bag).report.topics[0].rejected == 0
    [note] = _notes(bag)
    assert "1 pose(s) whose quaternion is unit only to" in note


def test_a_coordinate_flip_that_makes_a_spike_is_noted(
    sqlite_bag: Recorded, tmp_path: Path
) -> None:
    # y's sign bit, where |y| > 1.5 m: a jump of over 3 m and back within half a second, every
    # number finite and in range.
    bag = _flip_odometry(
        sqlite_bag,
        tmp_path,
        lambda pose: abs(pose.position.y) > 1.5,
        lambda lay: lay.poses[0] + 8,
        63,
    )
    [note] = _notes(bag)
    assert "1 pose(s) that leave both neighbours faster than 5 m/s" in note


def test_a_stamp_flip_is_noted(sqlite_bag: Recorded, tmp_path: Path) -> None:
    # The stamp's seconds gain 2**20 (12 days): out of order, and far from the receive time.
    bag = _flip_odometry(sqlite_bag, tmp_path, lambda pose: True, lambda lay: lay.stamps[0], 20)
    notes = _notes(bag)
    assert any("1 pose(s) whose header stamp breaks the order" in n for n in notes), notes
    assert any("1 message(s) of /odom carry a header stamp more than 1 s" in n for n in notes)


def test_two_recordings_that_disagree_on_a_message_are_noted(tmp_path: Path) -> None:
    """A low bit of x flipped in the split recording's copy of one pose: nothing in the message
    tells, but the full recording holds the same message (same header stamp) intact."""
    piece = tmp_path / "piece_3.bag"
    shutil.copy(TWICE / "split" / "piece_3.bag", piece)
    with AnyReader([piece]) as reader:
        [conn] = [c for c in reader.connections if c.topic == "/odom"]
        raw = bytes(next(iter(reader.messages(connections=[conn])))[2])
    layout = fastdecode.odometry_layout_ros1(raw)
    assert layout is not None
    data = bytearray(piece.read_bytes())
    at = data.index(raw) + layout.poses[0]
    data[at] ^= 1 << 3  # x's mantissa bit 3: 1e-15 m
    piece.write_bytes(bytes(data))
    full, damaged = ingest([TWICE / "full.bag", piece], tmp_path / "lake")
    assert full.error is None and damaged.error is None
    assert "1 pose_observed message(s) recorded differently" in damaged.note
    intact = ingest([TWICE / "split" / "piece_3.bag"], tmp_path / "lake")[0]
    assert "recorded differently" not in intact.note
