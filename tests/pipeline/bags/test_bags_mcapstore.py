"""Our ROS 2 bags as ``ros2 bag record`` writes them, checked with readers we did not write:
Foxglove's ``mcap`` (CRCs validated) and ``mcap-ros2-support`` (every message decoded from the
schema we stored), and the format of rosbag2's own test bags (QoS profiles)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from rosbags.highlevel import AnyReader
from ruamel.yaml import YAML

from objsearch.pipeline.bags.formats import BagFormat
from objsearch.ros.mcapstore import METADATA_VERSION

from .bag_fixtures import SHARED_BAGS, Recorded, record_run


def load_yaml(text: str) -> Any:
    return YAML(typ="safe", pure=True).load(text)


mcap_reader = pytest.importorskip("mcap.reader")
mcap_records = pytest.importorskip("mcap.records")

#: rmw's enum values, as rosbag2 writes them in metadata version 8 and earlier.
RELIABLE, BEST_EFFORT = 1, 2
TRANSIENT_LOCAL, VOLATILE = 1, 2
KEEP_LAST = 1
INFINITE = {"sec": 9_223_372_036, "nsec": 854_775_807}


@pytest.fixture(scope="module")
def zstd(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    return record_run(tmp_path_factory.mktemp("zstd"), BagFormat.ROS2_MCAP)


@pytest.fixture(scope="module")
def raw(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    return record_run(tmp_path_factory.mktemp("raw"), BagFormat.ROS2_MCAP, compress=False)


def mcap_file(rec: Recorded) -> Path:
    return Path(rec.bag) / f"{Path(rec.bag).name}.mcap"


def records(path: Path) -> list[Any]:
    """Every record, chunks as they are; before that, a pass that opens each chunk and checks
    every CRC (the reader raises on a mismatch)."""
    with path.open("rb") as fh:
        assert list(mcap_reader.StreamReader(fh, validate_crcs=True).records)
    with path.open("rb") as fh:
        return list(mcap_reader.StreamReader(fh, emit_chunks=True).records)


@pytest.mark.parametrize(("which", "compression"), [("zstd", "zstd"), ("raw", "")])
def test_chunks_and_crcs(request: pytest.FixtureRequest, which: str, compression: str) -> None:
    rec: Recorded = request.getfixturevalue(which)
    found = records(mcap_file(rec))
    header = found[0]
    assert isinstance(header, mcap_records.Header) and header.profile == "ros2"
    chunks = [r for r in found if isinstance(r, mcap_records.Chunk)]
    assert chunks and {c.compression for c in chunks} == {compression}
    assert all(c.uncompressed_crc != 0 for c in chunks)
    footer = found[-1]
    assert isinstance(footer, mcap_records.Footer) and footer.summary_crc != 0


def test_compressed_is_smaller(zstd: Recorded, raw: Recorded) -> None:
    small, large = mcap_file(zstd).stat().st_size, mcap_file(raw).stat().st_size
    assert small * 4 < large, (small, large)


def test_every_message_decodes_with_mcap_ros2(zstd: Recorded) -> None:
    from mcap_ros2.decoder import DecoderFactory

    counts: dict[str, int] = {}
    odometry = None
    with mcap_file(zstd).open("rb") as fh:
        reader = mcap_reader.make_reader(fh, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == "/odom" and odometry is None:
                odometry = (message.log_time, decoded)
    assert counts == zstd.recording.messages
    assert odometry is not None
    stamp, odom = odometry
    assert odom.header.stamp.sec * 10**9 + odom.header.stamp.nanosec == stamp
    assert odom.child_frame_id == "base_link"


def test_rosbags_reads_the_bag_it_did_not_write(zstd: Recorded) -> None:
    with AnyReader([zstd.bag]) as reader:
        assert sum(1 for _ in reader.messages()) == sum(zstd.recording.messages.values())
        qos = {c.topic: getattr(c.ext, "offered_qos_profiles") for c in reader.connections}  # noqa: B009
    (tf_static,) = qos["/tf_static"]
    assert (tf_static.durability.name, tf_static.reliability.name) == (
        "TRANSIENT_LOCAL",
        "RELIABLE",
    )
    assert (tf_static.history.name, tf_static.depth) == ("KEEP_LAST", 1)


def _profiles(text: str) -> list[dict[str, Any]]:
    loaded: list[dict[str, Any]] = load_yaml(text)
    return loaded


def test_qos_profiles_in_metadata_and_channels(zstd: Recorded) -> None:
    meta = load_yaml((zstd.bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == METADATA_VERSION
    topics = {
        t["topic_metadata"]["name"]: t["topic_metadata"] for t in meta["topics_with_message_count"]
    }
    with mcap_file(zstd).open("rb") as fh:
        summary = mcap_reader.make_reader(fh).get_summary()
    assert summary is not None
    channels = {c.topic: c.metadata for c in summary.channels.values()}
    assert set(topics) == set(channels)
    expected = {
        "/tf_static": (KEEP_LAST, 1, RELIABLE, TRANSIENT_LOCAL),
        "/tf": (KEEP_LAST, 100, RELIABLE, VOLATILE),
        "/odom": (KEEP_LAST, 10, RELIABLE, VOLATILE),
        "/objsearch/events": (KEEP_LAST, 1000, RELIABLE, VOLATILE),
    }
    for topic, text in ((t, m["offered_qos_profiles"]) for t, m in channels.items()):
        assert topics[topic]["offered_qos_profiles"] == text  # one text in both places
        (profile,) = _profiles(text)
        got = (profile["history"], profile["depth"], profile["reliability"], profile["durability"])
        assert got == expected.get(topic, (KEEP_LAST, 10, RELIABLE, VOLATILE)), topic
        assert profile["deadline"] == profile["lifespan"] == INFINITE
        assert channels[topic]["topic_type_hash"].startswith("RIHS01_")


def _rosbag2_test_bag_profiles() -> list[tuple[str, dict[str, Any]]]:
    """(where, profile) of every QoS profile rosbag2's own test bags hold (../shared)."""
    out = []
    for meta_path in sorted((SHARED_BAGS / "rosbag2").glob("*/metadata.yaml")):
        meta = load_yaml(meta_path.read_text())["rosbag2_bagfile_information"]
        for t in meta["topics_with_message_count"]:
            for p in _profiles(t["topic_metadata"]["offered_qos_profiles"]):
                out.append((str(meta_path), p))
    return out


def test_profiles_have_the_shape_of_rosbag2s_own(zstd: Recorded) -> None:
    theirs = _rosbag2_test_bag_profiles() if SHARED_BAGS.is_dir() else []
    if not theirs:
        pytest.skip(f"rosbag2's test bags are not at {SHARED_BAGS / 'rosbag2'} (../shared)")
    meta = load_yaml((zstd.bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    ours = [
        p for t in meta["topics_with_message_count"]
        for p in _profiles(t["topic_metadata"]["offered_qos_profiles"])
    ]  # fmt: skip
    for where, profile in theirs:
        for p in ours:
            assert p.keys() == profile.keys(), where
            for key, value in profile.items():
                assert type(p[key]) is type(value), (where, key)
    their_topic_keys = set()
    for meta_path in (SHARED_BAGS / "rosbag2").glob("*/metadata.yaml"):
        info = load_yaml(meta_path.read_text())["rosbag2_bagfile_information"]
        for t in info["topics_with_message_count"]:
            their_topic_keys |= set(t["topic_metadata"])
    assert their_topic_keys <= set(meta["topics_with_message_count"][0]["topic_metadata"])
