"""The byte-level odometry/TF decoders against rosbags' deserialisers, message by message."""

from __future__ import annotations

from pathlib import Path

import pytest
from bag_fixtures import Recorded
from objsearch.pipeline.bags import fastdecode
from objsearch.pipeline.bags.formats import detect
from objsearch.pipeline.bags.read import _odometry_fields, _transform_fields
from objsearch.pipeline.bags.topics import ACCEPTED_TYPES, Role
from objsearch.pipeline.bags.types import typestore

ODOM = ACCEPTED_TYPES[Role.ODOMETRY]
TF = ACCEPTED_TYPES[Role.TF]


def _compare(bag: Path) -> int:
    """Decode every odometry and TF message both ways; return how many were compared."""
    from rosbags.highlevel import AnyReader

    fmt = detect(bag)
    compared = 0
    with AnyReader([bag], default_typestore=typestore(fmt.distro)) as reader:
        conns = [c for c in reader.connections if c.msgtype in ODOM | TF]
        assert conns, f"{bag} has no odometry or TF to compare"
        for c, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, c.msgtype)
            if c.msgtype in ODOM:
                assert fastdecode.ODOMETRY[fmt.distro](raw) == _odometry_fields(msg)
            else:
                assert fastdecode.TF[fmt.distro](raw) == _transform_fields(msg)
            compared += 1
    return compared


def test_decoders_agree_with_rosbags_on_recorded_bags(recorded: Recorded) -> None:
    messages = recorded.recording.messages
    assert _compare(recorded.bag) == messages["/odom"] + messages["/tf"] + messages["/tf_static"]


@pytest.mark.parametrize(
    "name",
    ["rosbag.js/example.bag", "rosbag.js/example-lz4.bag", "embag/test.bag"],
)
def test_decoders_agree_with_rosbags_on_real_bags(shared_bags: Path, name: str) -> None:
    if not (shared_bags / name).exists():
        pytest.skip(f"{name} is not among the shared bags")
    assert _compare(shared_bags / name) > 0


def test_anything_but_the_standard_layout_falls_back(recorded: Recorded) -> None:
    from rosbags.highlevel import AnyReader

    fmt = detect(recorded.bag)
    decode = fastdecode.ODOMETRY[fmt.distro]
    with AnyReader([recorded.bag], default_typestore=typestore(fmt.distro)) as reader:
        [conn] = [c for c in reader.connections if c.topic == "/odom"]
        _, _, raw = next(iter(reader.messages(connections=[conn])))
    assert decode(raw) is not None
    assert decode(raw[:-8]) is None  # one double short
    assert decode(raw + b"\0" * 8) is None  # a field more than the standard type has
    assert decode(b"") is None
    if fmt.distro.value == "ros2":
        assert decode(b"\x00\x00" + raw[2:]) is None  # big-endian CDR: not decoded here
