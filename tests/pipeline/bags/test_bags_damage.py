"""Bags cut short and bytes flipped: salvage what is readable, say what was lost, never crash."""

from __future__ import annotations

import random
import shutil
from collections import Counter
from pathlib import Path

import pytest

from objsearch.events import Event
from objsearch.pipeline.bags.formats import BagFormat, storage_files
from objsearch.pipeline.bags.read import BagContents, read_bag

from .bag_fixtures import Recorded

CASES = 12  # per format and kind of damage; seeded


def _copy(recorded: Recorded, dest: Path) -> tuple[Path, Path]:
    """A copy of the bag and the file in it that holds the messages."""
    if recorded.bag.is_dir():
        shutil.copytree(recorded.bag, dest)
    else:
        dest = dest.with_suffix(".bag")
        shutil.copy(recorded.bag, dest)
    return dest, storage_files(dest)[0]


def _key(e: Event) -> tuple[object, ...]:
    # Derived events are renumbered when some are lost; compare them by time and content. A pose
    # may come from TF instead of odometry when one of the two topics is unusable (a flip in its
    # metadata): same pose, since map → odom is the identity in these recordings, but another
    # frame_id, so the frame is not compared.
    if e.type == "pose_observed":
        p = e.payload["pose"]
        return (e.type, e.time_ns, *(round(p[k], 9) for k in "xy"))
    if e.stream.startswith("bag:"):
        return (e.type, e.time_ns, repr(sorted(e.payload.items())))
    return (e.event_id, e.seq, e.type, repr(sorted(e.payload.items())), e.time_ns)


def _intact(recorded: Recorded) -> BagContents:
    return read_bag(recorded.bag)


def test_cut_bags_keep_a_prefix_and_report_the_loss(recorded: Recorded, tmp_path: Path) -> None:
    original = _intact(recorded)
    known = Counter(_key(e) for e in original.events)
    rng = random.Random(f"cut:{recorded.recording.format.value}")
    size = storage_files(recorded.bag)[0].stat().st_size
    salvaged_some = 0
    for i in range(CASES):
        bag, data = _copy(recorded, tmp_path / f"cut{i}")
        cut = rng.randrange(64, size - 1)
        with data.open("r+b") as fh:
            fh.truncate(cut)
        contents = read_bag(bag)  # must not raise
        got = Counter(_key(e) for e in contents.events)
        assert not (got - known), f"cut at {cut}: events that were never recorded"
        if len(contents.events) < len(original.events):
            assert contents.report.losses, f"cut at {cut}: events missing but no loss reported"
        salvaged_some += bool(contents.events)
        shutil.rmtree(bag) if bag.is_dir() else bag.unlink()
    # Cuts land anywhere in the file; most keep something before them.
    assert salvaged_some >= CASES // 2


def _messages_end(data: Path) -> int:
    """Where the messages end: an MCAP's summary starts there (its footer says where; with zstd
    chunks the summary, schemas included, is much of a small file); elsewhere the file's end."""
    raw = data.read_bytes()
    if raw.startswith(b"\x89MCAP"):
        # Footer: opcode, length, summary_start, summary_offset_start, summary_crc; then magic.
        summary_start = int.from_bytes(raw[-8 - 4 - 8 - 8 : -8 - 4 - 8], "little")
        if summary_start:
            return summary_start
    return len(raw)


def test_late_cut_loses_only_the_tail(recorded: Recorded, tmp_path: Path) -> None:
    original = _intact(recorded)
    bag, data = _copy(recorded, tmp_path / "late")
    with data.open("r+b") as fh:
        fh.truncate(int(_messages_end(data) * 0.7))
    contents = read_bag(bag)
    agent = [e for e in contents.events if not e.stream.startswith("bag:")]
    shift = contents.report.clock_offset_ns  # agent events on the bag's clock
    logged = [
        Event.from_json_dict({**e.to_json_dict(), "time_ns": e.time_ns + shift})
        for e in recorded.log
    ]
    # What survives of the agent's log is a gap-free prefix of it.
    assert agent == logged[: len(agent)]
    assert 0 < len(agent) < len(logged) or recorded.recording.format is BagFormat.ROS2_SQLITE3
    assert len(contents.events) < len(original.events)
    assert contents.report.reader == "salvage scan"
    assert contents.report.losses


def test_flipped_bytes_never_crash_and_are_accounted_for(
    recorded: Recorded, tmp_path: Path
) -> None:
    original = _intact(recorded)
    known = Counter(_key(e) for e in original.events)
    rng = random.Random(f"flip:{recorded.recording.format.value}")
    size = storage_files(recorded.bag)[0].stat().st_size
    for i in range(CASES):
        bag, data = _copy(recorded, tmp_path / f"flip{i}")
        flips = rng.randrange(1, 8)
        with data.open("r+b") as fh:
            for _ in range(flips):
                at = rng.randrange(0, size)
                fh.seek(at)
                byte = fh.read(1)
                fh.seek(at)
                fh.write(bytes([byte[0] ^ (1 << rng.randrange(8))]))
        contents = read_bag(bag)  # must not raise
        got = Counter(_key(e) for e in contents.events)
        changed = got - known
        # The agent's events carry a checksum: a damaged one is rejected, never stored.
        assert not [k for k in changed if str(k[0]) not in ("pose_observed", "objects_detected")]
        # A flip inside a number of a sensor message (no checksum in ROS 1, SQLite, or an MCAP
        # chunk without CRC) cannot be told from data; each flip can alter at most one message.
        assert sum(changed.values()) <= flips
        missing = sum((known - got).values()) - sum(changed.values())
        if missing > 0:
            report = contents.report
            assert report.losses or any(t.rejected for t in report.topics) or report.skipped, (
                f"case {i}: {missing} events missing without a word"
            )
        shutil.rmtree(bag) if bag.is_dir() else bag.unlink()


def test_garbage_is_not_a_bag(tmp_path: Path) -> None:
    from objsearch.pipeline.bags.errors import BagError

    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"not a bag at all")
    with pytest.raises(BagError, match="not a ROS bag"):
        read_bag(junk)
    with pytest.raises(BagError, match="no bag at"):
        read_bag(tmp_path / "missing.bag")
    empty = tmp_path / "emptydir"
    empty.mkdir()
    with pytest.raises(BagError, match=r"without \.db3 or \.mcap"):
        read_bag(empty)
