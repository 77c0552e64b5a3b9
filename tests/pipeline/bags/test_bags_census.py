"""What a bag says it holds (census.py), and ingest holding the readers to it."""

from __future__ import annotations

import shutil
import struct
import tomllib
from pathlib import Path

from devtools.bag_battery import ZERO_BLOCK, chunk_spans
from objsearch.pipeline.bags.census import take_census
from objsearch.pipeline.bags.formats import BagFormat, storage_files
from objsearch.pipeline.bags.read import read_bag

from .bag_fixtures import Recorded


def _copy(recorded: Recorded, dest: Path) -> tuple[Path, Path]:
    dest.mkdir()
    out = dest / recorded.bag.name
    if recorded.bag.is_dir():
        shutil.copytree(recorded.bag, out)
    else:
        shutil.copy(recorded.bag, out)
    return out, storage_files(out)[0]


def test_census_of_an_intact_bag_is_what_was_recorded(recorded: Recorded, tmp_path: Path) -> None:
    census = take_census(recorded.bag, recorded.recording.format.value)
    claimed, notes = census.per_topic()
    assert claimed == recorded.recording.messages
    assert census.complete and not notes
    # Without metadata.yaml the storage file's own index says the same.
    bag, _ = _copy(recorded, tmp_path / "copy")
    if bag.is_dir():
        (bag / "metadata.yaml").unlink()
    alone = take_census(bag, recorded.recording.format.value)
    assert alone.per_topic() == (recorded.recording.messages, [])
    assert alone.complete


def test_zeroed_block_in_a_chunk_is_lost_per_topic_never_silently(
    recorded: Recorded, tmp_path: Path
) -> None:
    fmt = recorded.recording.format
    start, end = chunk_spans(recorded.bag, fmt)[0]
    bag, data = _copy(recorded, tmp_path / "zeroed")
    buf = bytearray(data.read_bytes())
    # Past the chunk's middle: a ROS 1 chunk opens with its connection records, whose full
    # definitions (comments included) can fill its first half, and zeroing them loses no message.
    at = start + 3 * (end - start) // 4
    at -= at % ZERO_BLOCK if fmt is BagFormat.ROS2_SQLITE3 else 0  # a whole page
    buf[at : at + ZERO_BLOCK] = bytes(ZERO_BLOCK)
    data.write_bytes(bytes(buf))
    report = read_bag(bag).report
    intact = read_bag(recorded.bag).report
    assert report.claims_complete  # the bag's own index still counts every message
    by_topic = {t.topic: t for t in report.topics}
    skipped = {s.topic: s for s in report.skipped}
    lost = 0
    for t in intact.topics:
        if t.topic in skipped:  # its declaration was damaged: counted, not converted
            gone = skipped[t.topic].lost
            assert gone is not None and skipped[t.topic].messages + gone == t.messages
            lost += gone
            continue
        got = by_topic[t.topic]
        assert got.lost is not None and got.messages + got.lost == t.messages, t.topic
        assert got.claimed == t.messages
        lost += got.lost
        if got.lost:  # why: the damaged chunk, what AnyReader skipped, or rows not found
            assert got.lost_reasons, got
    assert lost > 0
    assert " lost (" in report.render()


def test_a_flipped_ros1_index_count_is_not_a_loss(recorded: Recorded, tmp_path: Path) -> None:
    if recorded.recording.format is not BagFormat.ROS1:
        return
    bag, data = _copy(recorded, tmp_path / "flipped")
    buf = bytearray(data.read_bytes())
    census = take_census(recorded.bag, "ros1").files[0]
    # The index section's first Chunk Info: flip a high bit of its first connection's count.
    first_chunk = min(census.chunks)
    needle = b"chunk_pos=" + struct.pack("<Q", first_chunk)
    header = buf.index(needle, first_chunk + 1)
    hstart = buf.rfind(b"\x04\x00\x00\x00op=\x06", 0, header) - 4
    (hlen,) = struct.unpack_from("<I", buf, hstart)
    data_at = hstart + 4 + hlen + 4
    buf[data_at + 4 + 2] ^= 0x20  # count (u32 after conn) gains 2**21
    data.write_bytes(bytes(buf))
    contents = read_bag(bag)
    assert all(t.lost == 0 for t in contents.report.topics)
    assert any("disagree" in n for n in contents.report.notes), contents.report.notes


def test_an_id_declared_as_two_topics_claims_nothing() -> None:
    """A flipped id in a channel record (5 → 4) declares id 4 twice: its counts belong to no
    known topic, so they are not claimed for either (seen by the battery as '151 lost > 16')."""
    from collections import Counter

    from objsearch.pipeline.bags.census import Census, FileCensus

    f = FileCensus(Path("run.mcap"), complete=True)
    f.declare(4, "/tf")
    f.declare(6, "/objsearch/detections")
    f.declare(4, "/camera/color/camera_info")  # the damaged record
    f.totals["MCAP statistics"] = Counter({4: 151, 5: 16, 6: 16})
    claimed, notes = Census((f,), None).per_topic()
    assert claimed == {"/objsearch/detections": 16}
    assert any("declared as different topics" in n for n in notes)


def _cut(recorded: Recorded, dest: Path, keep: int) -> Path:
    bag, data = _copy(recorded, dest)
    data.write_bytes(data.read_bytes()[:keep])
    return bag


def test_a_ros1_bag_cut_in_its_chunks_says_its_losses_are_not_known(
    ros1: Recorded, tmp_path: Path
) -> None:
    """Cut in the middle: the chunks after the cut and their counts are gone, so no topic's
    loss can be counted; the report says so (``lost`` None) rather than 0."""
    size = ros1.bag.stat().st_size
    report = read_bag(_cut(ros1, tmp_path / "cut", size // 2)).report
    assert not report.claims_complete and report.damaged
    read = {t.topic: t.messages for t in report.topics}
    assert sum(read.values()) < sum(ros1.recording.messages.values())
    for t in report.topics:
        assert t.lost is None, t
        assert t.lost_reasons, t
    assert "an unknown number lost" in report.render()
    assert any("header lists" in n and "chunks" in n for n in report.notes), report.notes


def test_a_ros1_bag_cut_in_its_index_section_counts_its_messages_exactly(
    ros1: Recorded, tmp_path: Path
) -> None:
    """Every chunk is whole, each followed by its Index Data records, and the bag header says
    how many chunks there are: the counts are exact (and the loss is 0), not lower bounds."""
    size = ros1.bag.stat().st_size
    report = read_bag(_cut(ros1, tmp_path / "cut", size - 100)).report
    assert report.claims_complete
    for t in report.topics:
        assert (t.messages, t.claimed, t.lost) == (ros1.recording.messages[t.topic],) * 2 + (0,)


def test_a_missing_yaml_reader_is_not_taken_for_a_missing_claim(tmp_path: Path) -> None:
    """metadata.yaml is read with ruamel.yaml, a declared dependency: without it the census says
    so (ImportError), it does not report the claim as absent (as ``except Exception`` did)."""
    import subprocess
    import sys

    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n", encoding="utf-8")
    code = (
        "import sys\nsys.modules['ruamel.yaml'] = None\n"
        "from objsearch.pipeline.bags.census import metadata_counts\n"
        f"metadata_counts(__import__('pathlib').Path({str(bag)!r}))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 1
    assert "ImportError" in proc.stderr or "ModuleNotFoundError" in proc.stderr
    doc = tomllib.loads((Path(__file__).resolve().parents[3] / "pyproject.toml").read_text())
    assert any(d.startswith("ruamel.yaml") for d in doc["project"]["dependencies"])
