"""Every single-bit flip of some odometry messages of a SQLite bag: what the pose track does.

    python benchmarks/odometry_flips.py [--messages 10] [--seed 7]

A rosbag2 SQLite bag has no checksum, so a flipped bit in a message reaches ingest as it is.
This records one simulated run to SQLite (scene 1, targets Apple and Cup, start kitchen-1,
odometry at 2 Hz, as the tests' recordings), picks ``--messages`` of its odometry messages
(seeded), and for every bit of each builds the topic's pose track (``posetrack.convert_sources``,
what ingest runs) with that one message flipped. Each flip is counted as: rejected (the message
makes no pose); unchanged (the pose and its stamp are the intact ones; "noted" if the report
still notes the topic, e.g. a flip in an unused quaternion component); changed and noted; or
changed and silent — the last two split by size (more than 5 cm, 0.01 rad or 0.1 s: "large").
Prints the counts.
"""

from __future__ import annotations

import argparse
import math
import random
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

from rosbags.highlevel import AnyReader

from objsearch.pipeline.bags import fastdecode
from objsearch.pipeline.bags.formats import BagFormat
from objsearch.pipeline.bags.posetrack import PoseStream, convert_sources
from objsearch.pipeline.bags.record import record
from objsearch.ros.topics import TopicMap
from objsearch.ros.types import Distro, typestore

Pose = tuple[float, float, float, int]  # x, y, yaw, stamp


def _track(messages: list[tuple[int, bytes]]) -> tuple[dict[int, Pose], bool]:
    """The pose of each message (by its index), and whether the topic got a note."""
    store = typestore(Distro.ROS2)

    def deserialize(raw: bytes, msgtype: str) -> Any:
        return store.deserialize_cdr(raw, msgtype)

    source = PoseStream(
        "/odom", "nav_msgs/msg/Odometry", False, fastdecode.ODOMETRY_LAYOUT[Distro.ROS2]
    )
    for i, (t, raw) in enumerate(messages):
        source.add(t, i, raw, deserialize)
    poses, [outcome] = convert_sources([source], TopicMap().frames)
    rows = zip(
        poses.arrival.tolist(),
        poses.x.tolist(),
        poses.y.tolist(),
        poses.yaw.tolist(),
        poses.stamp.tolist(),
        strict=True,
    )
    return {a: (x, y, yaw, s) for a, x, y, yaw, s in rows}, bool(outcome.suspects)


def _large(a: Pose, b: Pose) -> bool:
    turn = abs(math.remainder(a[2] - b[2], 2 * math.pi))
    return math.hypot(a[0] - b[0], a[1] - b[1]) > 0.05 or turn > 0.01 or abs(a[3] - b[3]) > 10**8


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--messages", type=int, default=10)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "run"
        record(
            bag,
            BagFormat.ROS2_SQLITE3,
            scenes=[1],
            targets=["Apple", "Cup"],
            starts=["kitchen-1"],
            odom_hz=2.0,
        )
        with AnyReader([bag], default_typestore=typestore(Distro.ROS2)) as reader:
            [conn] = [c for c in reader.connections if c.topic == "/odom"]
            messages = [(t, bytes(raw)) for _, t, raw in reader.messages(connections=[conn])]
    intact, noted = _track(messages)
    assert not noted, "the intact recording is noted"
    picks = random.Random(args.seed).sample(range(len(messages)), args.messages)
    counts: Counter[str] = Counter()
    started = time.perf_counter()
    for m in picks:
        t, raw = messages[m]
        for bit in range(8 * len(raw)):
            flipped = bytearray(raw)
            flipped[bit // 8] ^= 1 << (bit % 8)
            variant = [*messages[:m], (t, bytes(flipped)), *messages[m + 1 :]]
            poses, noted = _track(variant)
            if m not in poses:
                counts["rejected"] += 1
            elif poses[m] == intact[m]:
                counts["unchanged, noted" if noted else "unchanged"] += 1
            else:
                size = "large" if _large(poses[m], intact[m]) else "small"
                counts[f"changed, {'noted' if noted else 'silent'}, {size}"] += 1
    total = sum(counts.values())
    print(
        f"{len(messages)} odometry messages of {len(raw)} bytes; {args.messages} picked "
        f"(seed {args.seed}); {total} single-bit flips, {time.perf_counter() - started:.0f} s"
    )
    for key in (
        "rejected",
        "unchanged",
        "unchanged, noted",
        "changed, noted, large",
        "changed, noted, small",
        "changed, silent, large",
        "changed, silent, small",
    ):
        print(f"  {key:24} {counts[key]:6}  {100 * counts[key] / total:5.1f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
