"""The byte-level odometry/TF decoders against rosbags' deserialisers, message by message
(the batch decoder's header stamps too)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from objsearch.pipeline.bags import fastdecode
from objsearch.pipeline.bags.formats import detect
from objsearch.pipeline.bags.posetrack import odometry_fields, stamp_ns, transform_fields
from objsearch.ros.topics import ACCEPTED_TYPES, Role
from objsearch.ros.types import typestore

from .bag_fixtures import Recorded

ODOM = ACCEPTED_TYPES[Role.ODOMETRY]
TF = ACCEPTED_TYPES[Role.TF]


def _compare(bag: Path) -> int:
    """Decode every odometry and TF message both ways, one by one and in batches per
    connection; return how many were compared."""
    from rosbags.highlevel import AnyReader

    fmt = detect(bag)
    compared = 0
    with AnyReader([bag], default_typestore=typestore(fmt.distro)) as reader:
        conns = [c for c in reader.connections if c.msgtype in ODOM | TF]
        assert conns, f"{bag} has no odometry or TF to compare"
        for conn in conns:
            raws, expected = [], []
            for c, _, raw in reader.messages(connections=[conn]):
                msg: Any = reader.deserialize(raw, c.msgtype)
                if c.msgtype in ODOM:
                    fields = odometry_fields(msg)
                    assert fastdecode.ODOMETRY[fmt.distro](raw) == fields
                    expected.append([(fields[0], "", *fields[1:], stamp_ns(msg.header))])
                else:
                    transforms = transform_fields(msg)
                    assert fastdecode.TF[fmt.distro](raw) == transforms
                    stamps = [stamp_ns(t.header) for t in msg.transforms]
                    expected.append([(*t, s) for t, s in zip(transforms, stamps, strict=True)])
                raws.append(raw)
                compared += 1
            tf = conn.msgtype in TF
            layouts = fastdecode.TF_LAYOUT if tf else fastdecode.ODOMETRY_LAYOUT
            assert _batch(raws, layouts[fmt.distro], tf) == expected
    return compared


def _batch(
    raws: list[bytes], layout: fastdecode.LayoutReader, tf: bool
) -> list[list[tuple[object, ...]]]:
    """decode_batch's rows, per message in transform order, as the single decoders give them,
    each with its header stamp."""
    d = fastdecode.decode_batch(raws, layout, tf=tf)
    assert d.undecoded == ()
    frames = [*d.frames, ""]  # code -1: no child (odometry)
    rows = sorted(zip(d.message.tolist(), d.index.tolist(), range(len(d.message)), strict=True))
    out: list[list[tuple[object, ...]]] = [[] for _ in raws]
    for m, _, r in rows:
        values = (float(v[r]) for v in (d.x, d.y, d.qx, d.qy, d.qz, d.qw))
        out[m].append((frames[d.parent[r]], frames[d.child[r]], *values, int(d.stamp[r])))
    return out


def test_decoders_agree_with_rosbags_on_recorded_bags(recorded: Recorded) -> None:
    messages = recorded.recording.messages
    assert _compare(recorded.bag) == messages["/odom"] + messages["/tf"] + messages["/tf_static"]


@pytest.mark.parametrize(
    "name",
    ["rosbag.js/example.bag", "rosbag.js/example-lz4.bag", "embag/test.bag"],
)
def test_decoders_agree_with_rosbags_on_real_bags(shared_bags: Path, name: str) -> None:
    assert (shared_bags / name).exists(), f"{name} is not among the shared bags"
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


def test_the_batch_decoder_groups_layouts_and_leaves_the_rest(recorded: Recorded) -> None:
    from rosbags.highlevel import AnyReader

    fmt = detect(recorded.bag)
    layout = fastdecode.ODOMETRY_LAYOUT[fmt.distro]
    with AnyReader([recorded.bag], default_typestore=typestore(fmt.distro)) as reader:
        [conn] = [c for c in reader.connections if c.topic == "/odom"]
        raws = [raw for _, _, raw in reader.messages(connections=[conn])][:20]
    # Same length, other frame names: another layout of the same length, decoded too.
    renamed = [r.replace(b"odom", b"odoM") for r in raws[:5]]
    broken = [raws[0][:-8], b"", raws[1] + b"\0" * 8]
    d = fastdecode.decode_batch([*raws, *renamed, *broken], layout, tf=False)
    n = len(raws) + len(renamed)
    assert sorted(d.message.tolist()) == list(range(n))
    assert d.undecoded == (n, n + 1, n + 2)
    assert {d.frames[c] for c in d.parent[d.message >= len(raws)].tolist()} == {"odoM"}
    single = [fastdecode.odometry_fields(r, layout) for r in [*raws, *renamed]]
    for row, m in enumerate(d.message.tolist()):
        assert single[m] == (
            d.frames[d.parent[row]],
            *(float(v[row]) for v in (d.x, d.y, d.qx, d.qy, d.qz, d.qw)),
        )
