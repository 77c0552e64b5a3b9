"""ROS 1 bags store each type's full definition as ``rosbag record`` does: the ``.msg`` text with
its comments, dependencies in genmsg's order (compared with bags the real recorder wrote)."""

from __future__ import annotations

from pathlib import Path

import pytest
from rosbags.rosbag1 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from objsearch.pipeline.bags.formats import BagFormat
from objsearch.pipeline.bags.record import MSG_TYPES
from objsearch.pipeline.bags.ros1defs import SEPARATOR, full_definition
from objsearch.ros.types import Distro, typestore

from .bag_fixtures import SHARED_BAGS, record_run


def test_every_type_we_record_has_its_msg_text() -> None:
    store = typestore(Distro.ROS1)
    for msgtype in set(MSG_TYPES.values()):
        text = full_definition(store, msgtype)
        assert text is not None, msgtype
        assert "#" in text, msgtype  # comments kept


def test_the_bag_stores_them_and_their_md5s_hold(tmp_path: Path) -> None:
    rec = record_run(tmp_path, BagFormat.ROS1)
    store = typestore(Distro.ROS1)
    with Reader(rec.bag) as reader:
        connections = list(reader.connections)
    assert connections
    for conn in connections:
        assert conn.msgdef.data == full_definition(store, conn.msgtype), conn.topic
        # A reader that knows nothing of the type rebuilds it from the stored text alone.
        fresh = get_typestore(Stores.EMPTY)
        fresh.register(get_types_from_msg(conn.msgdef.data, conn.msgtype))
        assert fresh.generate_msgdef(conn.msgtype)[1] == conn.digest, conn.topic


def _stored(msgtype: str) -> tuple[str, str] | None:
    """(definition, md5) of ``msgtype`` as a real ``rosbag record`` stored it (../shared)."""
    for path in sorted(SHARED_BAGS.rglob("*.bag")):
        with Reader(path) as reader:
            for conn in reader.connections:
                if conn.msgtype == msgtype:
                    return conn.msgdef.data, conn.digest
    return None


def _without_comments(text: str) -> list[str]:
    lines = (line.split("#", 1)[0].rstrip() for line in text.splitlines())
    return [line for line in lines if line]


@pytest.mark.parametrize(
    ("msgtype", "exact"),
    [
        # Recorded on Noetic-era common_msgs: the same text to the byte.
        ("sensor_msgs/msg/CameraInfo", True),
        ("sensor_msgs/msg/Image", True),
        # Recorded on older distros whose comments differ; fields and order must not.
        ("nav_msgs/msg/Odometry", False),
        ("tf2_msgs/msg/TFMessage", False),
    ],
)
def test_same_text_as_the_real_recorder(msgtype: str, exact: bool) -> None:
    if not SHARED_BAGS.is_dir():
        pytest.skip(f"the shared real bags are not at {SHARED_BAGS} (../shared is absent)")
    stored = _stored(msgtype)
    assert stored is not None, f"no {msgtype} in the shared bags"
    theirs, md5 = stored
    store = typestore(Distro.ROS1)
    ours = full_definition(store, msgtype)
    assert ours is not None
    assert store.generate_msgdef(msgtype)[1] == md5
    if exact:
        assert ours == theirs
    else:
        assert _without_comments(ours) == _without_comments(theirs)
        assert ours.count(SEPARATOR) == theirs.count(SEPARATOR)
