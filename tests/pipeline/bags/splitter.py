"""Cut a ROS 1 bag the way ``rosbag record --split --duration=D`` does; re-time one as a
playback recorded again does.

The real recorder (``rosbag/recorder.cpp``) starts a new file when a message arrives more than
``D`` after the current file was opened; each file is a complete bag of its own, holding whole
messages and a connection record (topic, type, MD5, full definition, caller id) for every topic
written into it. Files are named ``<prefix>_<n>.bag``. This does the same from a recorded bag,
using the bag's own receive times, definitions and MD5s.
"""

from __future__ import annotations

from pathlib import Path

from rosbags.interfaces import Connection, ConnectionExtRosbag1
from rosbags.rosbag1 import Reader, Writer


def split_ros1(bag: Path, out_dir: Path, duration_s: float) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    pieces: list[Path] = []
    writer: Writer | None = None
    opened_ns = 0
    conns: dict[int, Connection] = {}
    with Reader(bag) as reader:
        for conn, t, raw in reader.messages():
            if writer is None or t - opened_ns > duration_s * 1e9:
                if writer is not None:
                    writer.close()
                path = out_dir / f"{bag.stem}_{len(pieces)}.bag"
                writer = Writer(path)
                writer.open()
                pieces.append(path)
                opened_ns = t
                conns = {}
            if conn.id not in conns:
                conns[conn.id] = _copy_connection(writer, conn)
            writer.write(conns[conn.id], t, raw)
    if writer is not None:
        writer.close()
    return pieces


def rerecord_ros1(bag: Path, out: Path, *, rate: float, start_ns: int) -> Path:
    """The bag as ``rosbag play -r RATE`` → ``rosbag record`` would store it: every message
    unchanged (header stamps included), received at ``start_ns`` + (its time in ``bag`` since
    the first message) / ``rate`` on the recorder's clock."""
    conns: dict[int, Connection] = {}
    with Reader(bag) as reader, Writer(out) as writer:
        first: int | None = None
        for conn, t, raw in reader.messages():
            first = t if first is None else first
            if conn.id not in conns:
                conns[conn.id] = _copy_connection(writer, conn)
            writer.write(conns[conn.id], start_ns + round((t - first) / rate), raw)
    return out


def _copy_connection(writer: Writer, conn: Connection) -> Connection:
    """``conn`` of a ROS 1 bag added to ``writer`` as it was (definition, caller, latching)."""
    ext = conn.ext
    assert isinstance(ext, ConnectionExtRosbag1)
    return writer.add_connection(
        conn.topic,
        conn.msgtype,
        msgdef=conn.msgdef.data,
        md5sum=conn.digest,
        callerid=ext.callerid,
        latching=ext.latching,
    )
