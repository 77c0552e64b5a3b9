"""Read the few fields ingest needs from odometry and TF messages straight from their bytes.

A full deserialisation of ``nav_msgs/Odometry`` builds a dozen nested objects and two numpy
covariance arrays to hand ingest seven numbers; odometry and TF are nearly all of a robot's
converted messages. These decoders read the fixed layouts of the standard types (ROS 1 and
little-endian CDR) and insist that the layout accounts for every byte of the message (CDR: up to
3 bytes of end padding). Anything else — another definition under the same name, a damaged
length, big-endian CDR — is left to the caller, which deserialises the message the ordinary way,
so a decoder can only be faster, never decide differently.

Two ways to run the one decoder: :func:`odometry_cdr` & co. read one message; :func:`decode_batch`
reads many at once. A message's :class:`Layout` (frame names, where its poses are) is decided by
a few byte ranges only — the encapsulation header, the transform count, the string lengths and
strings — plus its length. So the batch decoder reads the layout of one message and takes every
message of the same length whose deciding bytes are equal to that one's as having the same
layout, reading their poses with numpy at the same offsets; the others go one by one.
(`tests/pipeline/bags/test_bags_fastdecode.py` checks both against rosbags on every message of
the recorded and the shared real bags.)
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Final

import numpy as np
import numpy.typing as npt

from objsearch.ros.types import Distro

#: (frame_id, x, y, qx, qy, qz, qw): an odometry message's header frame and planar pose. (The
#: header stamps are read by :func:`decode_batch` only, at the offsets :class:`Layout` gives.)
OdomFields = tuple[str, float, float, float, float, float, float]
#: (parent frame, child frame, x, y, qx, qy, qz, qw) per transform of a TF message.
TransformFields = tuple[str, str, float, float, float, float, float, float]

_U32_LE: Final = struct.Struct("<I")
_POSE_LE: Final = struct.Struct("<7d")  # position x y z, orientation x y z w
_POSE_BYTES: Final = _POSE_LE.size
_ODOM_TAIL: Final = 85 * 8  # pose (7) + covariance (36) + twist (6) + covariance (36) doubles
_TRANSFORM: Final = 7 * 8  # translation (3) + rotation (4) doubles
_CDR_LE: Final = b"\x00\x01"
_MAX_TRANSFORMS: Final = 100_000
#: A length group tries this many layouts in bulk before decoding its remaining messages singly.
_MAX_TEMPLATES: Final = 8


@dataclass(frozen=True, slots=True)
class Layout:
    """Where one message's poses are, and the bytes that decided it."""

    #: Odometry: (header frame,). TF: (parent, child) per transform.
    frames: tuple[str, ...]
    #: Offset of each pose's 7 little-endian doubles (position x y z, orientation x y z w).
    poses: tuple[int, ...]
    #: The byte ranges [start, end) the layout was read from; with the message's length they
    #: determine it.
    deciding: tuple[tuple[int, int], ...]
    #: Offset of each pose's header stamp: seconds, then nanoseconds, 4 little-endian bytes each.
    stamps: tuple[int, ...] = ()
    #: The seconds are signed (CDR's ``builtin_interfaces/Time``) rather than unsigned (ROS 1).
    signed: bool = False


LayoutReader = Callable[[bytes], Layout | None]


def _string_cdr(raw: bytes, pos: int, deciding: list[tuple[int, int]]) -> tuple[str, int]:
    pos = (pos + 3) & ~3  # the data starts at 4, so 4-alignment to it is absolute
    (n,) = _U32_LE.unpack_from(raw, pos)
    end = pos + 4 + n
    if n == 0 or end > len(raw) or raw[end - 1] != 0:
        raise ValueError("not a CDR string")
    deciding.append((pos, end))
    return raw[pos + 4 : end - 1].decode(), end


def _align8_cdr(pos: int) -> int:
    # CDR aligns to the start of the data, which follows the 4-byte encapsulation header.
    return 4 + ((pos - 4 + 7) & ~7)


def _string_ros1(raw: bytes, pos: int, deciding: list[tuple[int, int]]) -> tuple[str, int]:
    (n,) = _U32_LE.unpack_from(raw, pos)
    end = pos + 4 + n
    if end > len(raw):
        raise ValueError("not a ROS 1 string")
    deciding.append((pos, end))
    return raw[pos + 4 : end].decode(), end


def _cdr_complete(raw: bytes, end: int) -> bool:
    return end <= len(raw) < end + 4


_NOT_DECODED: Final = (ValueError, struct.error, UnicodeDecodeError)


def odometry_layout_cdr(raw: bytes) -> Layout | None:
    deciding = [(0, 2)]
    try:
        if raw[:2] != _CDR_LE:
            return None
        frame, pos = _string_cdr(raw, 4 + 8, deciding)  # after the header's stamp
        _, pos = _string_cdr(raw, pos, deciding)  # child_frame_id
    except _NOT_DECODED:
        return None
    pos = _align8_cdr(pos)
    if not _cdr_complete(raw, pos + _ODOM_TAIL):
        return None
    return Layout((frame,), (pos,), tuple(deciding), (4,), signed=True)


def odometry_layout_ros1(raw: bytes) -> Layout | None:
    deciding: list[tuple[int, int]] = []
    try:
        frame, pos = _string_ros1(raw, 12, deciding)  # after the header's seq, sec, nsec
        _, pos = _string_ros1(raw, pos, deciding)
    except _NOT_DECODED:
        return None
    if len(raw) != pos + _ODOM_TAIL:
        return None
    return Layout((frame,), (pos,), tuple(deciding), (4,))  # after the header's seq


def tf_layout_cdr(raw: bytes) -> Layout | None:
    deciding = [(0, 2), (4, 8)]
    try:
        if raw[:2] != _CDR_LE:
            return None
        (count,) = _U32_LE.unpack_from(raw, 4)
        if count > _MAX_TRANSFORMS:
            return None
        pos = 8
        frames: list[str] = []
        poses = []
        stamps = []
        for _ in range(count):
            stamps.append((pos + 3) & ~3)
            parent, pos = _string_cdr(raw, stamps[-1] + 8, deciding)  # stamp, frame_id
            child, pos = _string_cdr(raw, pos, deciding)
            pos = _align8_cdr(pos)
            frames += (parent, child)
            poses.append(pos)
            pos += _TRANSFORM
    except _NOT_DECODED:
        return None
    if not _cdr_complete(raw, pos):
        return None
    return Layout(tuple(frames), tuple(poses), tuple(deciding), tuple(stamps), signed=True)


def tf_layout_ros1(raw: bytes) -> Layout | None:
    deciding = [(0, 4)]
    try:
        (count,) = _U32_LE.unpack_from(raw, 0)
        if count > _MAX_TRANSFORMS:
            return None
        pos = 4
        frames: list[str] = []
        poses = []
        stamps = []
        for _ in range(count):
            stamps.append(pos + 4)
            parent, pos = _string_ros1(raw, pos + 12, deciding)  # header seq, sec, nsec
            child, pos = _string_ros1(raw, pos, deciding)
            frames += (parent, child)
            poses.append(pos)
            pos += _TRANSFORM
    except _NOT_DECODED:
        return None
    if pos != len(raw):
        return None
    return Layout(tuple(frames), tuple(poses), tuple(deciding), tuple(stamps))


def _pose(raw: bytes, pos: int) -> tuple[float, float, float, float, float, float]:
    x, y, _, qx, qy, qz, qw = _POSE_LE.unpack_from(raw, pos)
    return x, y, qx, qy, qz, qw


def odometry_fields(raw: bytes, layout: LayoutReader) -> OdomFields | None:
    """One odometry message's fields, or ``None`` when it is not in the standard layout."""
    found = layout(raw)
    return None if found is None else (found.frames[0], *_pose(raw, found.poses[0]))


def transform_fields(raw: bytes, layout: LayoutReader) -> list[TransformFields] | None:
    """One TF message's transforms, or ``None`` when it is not in the standard layout."""
    found = layout(raw)
    if found is None:
        return None
    f = found.frames
    return [(f[2 * i], f[2 * i + 1], *_pose(raw, p)) for i, p in enumerate(found.poses)]


def odometry_cdr(raw: bytes) -> OdomFields | None:
    return odometry_fields(raw, odometry_layout_cdr)


def odometry_ros1(raw: bytes) -> OdomFields | None:
    return odometry_fields(raw, odometry_layout_ros1)


def tf_cdr(raw: bytes) -> list[TransformFields] | None:
    return transform_fields(raw, tf_layout_cdr)


def tf_ros1(raw: bytes) -> list[TransformFields] | None:
    return transform_fields(raw, tf_layout_ros1)


ODOMETRY_LAYOUT: Final[dict[Distro, LayoutReader]] = {
    Distro.ROS1: odometry_layout_ros1,
    Distro.ROS2: odometry_layout_cdr,
}
TF_LAYOUT: Final[dict[Distro, LayoutReader]] = {
    Distro.ROS1: tf_layout_ros1,
    Distro.ROS2: tf_layout_cdr,
}
ODOMETRY: Final = {Distro.ROS1: odometry_ros1, Distro.ROS2: odometry_cdr}
TF: Final = {Distro.ROS1: tf_ros1, Distro.ROS2: tf_cdr}


Floats = npt.NDArray[np.float64]
Ints = npt.NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class Decoded:
    """The poses of a batch of messages, one row per pose (odometry: one per message; TF: one
    per transform, in message order then transform order)."""

    message: Ints  # the message's index in the batch
    index: Ints  # the transform's index in its message (0 for odometry)
    frames: tuple[str, ...]  # the frame names the codes below refer to
    parent: Ints  # code of the header frame (odometry) or parent frame (TF)
    child: Ints  # code of the child frame (TF; -1 for odometry)
    x: Floats
    y: Floats
    qx: Floats
    qy: Floats
    qz: Floats
    qw: Floats
    #: Indices of messages not in the standard layout (for the caller's deserialiser).
    undecoded: tuple[int, ...]
    #: Each pose's header stamp (ns since the epoch; 0 where the header has none).
    stamp: Ints = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


def decode_batch(raws: Sequence[bytes], layout: LayoutReader, *, tf: bool) -> Decoded:
    """Decode a batch of odometry (``tf=False``) or TF messages of one connection."""
    lengths = np.fromiter(map(len, raws), dtype=np.int64, count=len(raws))
    frames: dict[str, int] = {}
    parts: list[tuple[Ints, Layout, npt.NDArray[np.uint8]]] = []
    undecoded: list[int] = []
    for length in np.unique(lengths).tolist():
        members = np.flatnonzero(lengths == length)
        block = np.frombuffer(b"".join([raws[i] for i in members.tolist()]), dtype=np.uint8)
        block = block.reshape(len(members), length)
        rows = np.arange(len(members))
        for _ in range(_MAX_TEMPLATES):
            if not len(rows):
                break
            first = int(rows[0])
            found = layout(raws[int(members[first])])
            if found is None:
                undecoded.append(int(members[first]))
                rows = rows[1:]
                continue
            same = np.ones(len(rows), dtype=bool)
            for a, b in found.deciding:
                same &= (block[rows, a:b] == block[first, a:b]).all(axis=1)
            parts.append((members[rows[same]], found, block[rows[same]]))
            rows = rows[~same]
        for r in rows.tolist():  # more layouts in one length than is worth doing in bulk
            i = int(members[r])
            found = layout(raws[i])
            if found is None:
                undecoded.append(i)
            else:
                parts.append((np.array([i], dtype=np.int64), found, block[r : r + 1]))
    message, index, parent, child, values, stamps = [], [], [], [], [], []
    for which, found, data in parts:
        codes = [frames.setdefault(f, len(frames)) for f in found.frames]
        for k, pos in enumerate(found.poses):
            n = len(which)
            message.append(which)
            index.append(np.full(n, k, dtype=np.int64))
            parent.append(np.full(n, codes[2 * k] if tf else codes[0], dtype=np.int64))
            child.append(np.full(n, codes[2 * k + 1] if tf else -1, dtype=np.int64))
            values.append(np.ascontiguousarray(data[:, pos : pos + _POSE_BYTES]).view("<f8"))
            stamps.append(_stamps(data, found.stamps[k], found.signed))
    if not parts:
        no_ints, no_floats = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.float64)
        return Decoded(
            no_ints,
            no_ints,
            (),
            no_ints,
            no_ints,
            *(no_floats,) * 6,  # x, y, qx, qy, qz, qw
            tuple(sorted(undecoded)),
            no_ints,
        )
    pose = np.concatenate(values).astype(np.float64, copy=False)
    return Decoded(
        np.concatenate(message),
        np.concatenate(index),
        tuple(frames),
        np.concatenate(parent),
        np.concatenate(child),
        pose[:, 0].copy(),
        pose[:, 1].copy(),
        pose[:, 3].copy(),
        pose[:, 4].copy(),
        pose[:, 5].copy(),
        pose[:, 6].copy(),
        tuple(sorted(undecoded)),
        np.concatenate(stamps),
    )


def _stamps(data: npt.NDArray[np.uint8], pos: int, signed: bool) -> Ints:
    """The header stamps (ns) at ``pos`` of each message (row) of ``data``."""
    sec = np.ascontiguousarray(data[:, pos : pos + 4]).view("<i4" if signed else "<u4")
    nsec = np.ascontiguousarray(data[:, pos + 4 : pos + 8]).view("<u4")
    return sec[:, 0].astype(np.int64) * 1_000_000_000 + nsec[:, 0].astype(np.int64)
