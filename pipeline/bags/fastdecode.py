"""Read the few fields ingest needs from odometry and TF messages straight from their bytes.

A full deserialisation of ``nav_msgs/Odometry`` builds a dozen nested objects and two numpy
covariance arrays to hand ingest seven numbers; odometry and TF are nearly all of a robot's
converted messages. These decoders read the fixed layouts of the standard types (ROS 1 and
little-endian CDR) with :mod:`struct` and insist that the layout accounts for every byte of the
message (CDR: up to 3 bytes of end padding). Anything else — another definition under the same
name, a damaged length, big-endian CDR — returns ``None`` and the caller deserialises the
message the ordinary way, so a decoder can only be faster, never decide differently.
(`tests/pipeline/bags/test_bags_fastdecode.py` checks them against rosbags on every message of
the recorded and the shared real bags.)
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Final

from objsearch.pipeline.bags.types import Distro

#: (frame_id, x, y, qx, qy, qz, qw): an odometry message's header frame and planar pose.
OdomFields = tuple[str, float, float, float, float, float, float]
#: (parent frame, child frame, x, y, qx, qy, qz, qw) per transform of a TF message.
TransformFields = tuple[str, str, float, float, float, float, float, float]

OdomDecoder = Callable[[bytes], OdomFields | None]
TFDecoder = Callable[[bytes], list[TransformFields] | None]

_U32_LE: Final = struct.Struct("<I")
_POSE_LE: Final = struct.Struct("<7d")  # position x y z, orientation x y z w
_ODOM_TAIL: Final = 85 * 8  # pose (7) + covariance (36) + twist (6) + covariance (36) doubles
_TRANSFORM: Final = 7 * 8  # translation (3) + rotation (4) doubles
_CDR_LE: Final = b"\x00\x01"
_MAX_TRANSFORMS: Final = 100_000


def _string_cdr(raw: bytes, pos: int) -> tuple[str, int]:
    pos = (pos + 3) & ~3  # the data starts at 4, so 4-alignment to it is absolute
    (n,) = _U32_LE.unpack_from(raw, pos)
    end = pos + 4 + n
    if n == 0 or end > len(raw) or raw[end - 1] != 0:
        raise ValueError("not a CDR string")
    return raw[pos + 4 : end - 1].decode(), end


def _align8_cdr(pos: int) -> int:
    # CDR aligns to the start of the data, which follows the 4-byte encapsulation header.
    return 4 + ((pos - 4 + 7) & ~7)


def _string_ros1(raw: bytes, pos: int) -> tuple[str, int]:
    (n,) = _U32_LE.unpack_from(raw, pos)
    end = pos + 4 + n
    if end > len(raw):
        raise ValueError("not a ROS 1 string")
    return raw[pos + 4 : end].decode(), end


def _cdr_complete(raw: bytes, end: int) -> bool:
    return end <= len(raw) < end + 4


def odometry_cdr(raw: bytes) -> OdomFields | None:
    try:
        if raw[:2] != _CDR_LE:
            return None
        frame, pos = _string_cdr(raw, 4 + 8)  # after the header's stamp (sec, nanosec)
        _, pos = _string_cdr(raw, pos)  # child_frame_id
        pos = _align8_cdr(pos)
        if not _cdr_complete(raw, pos + _ODOM_TAIL):
            return None
        x, y, _, qx, qy, qz, qw = _POSE_LE.unpack_from(raw, pos)
    except (ValueError, struct.error, UnicodeDecodeError):
        return None
    return frame, x, y, qx, qy, qz, qw


def odometry_ros1(raw: bytes) -> OdomFields | None:
    try:
        frame, pos = _string_ros1(raw, 12)  # after the header's seq, sec, nsec
        _, pos = _string_ros1(raw, pos)
        if len(raw) != pos + _ODOM_TAIL:
            return None
        x, y, _, qx, qy, qz, qw = _POSE_LE.unpack_from(raw, pos)
    except (ValueError, struct.error, UnicodeDecodeError):
        return None
    return frame, x, y, qx, qy, qz, qw


def tf_cdr(raw: bytes) -> list[TransformFields] | None:
    try:
        if raw[:2] != _CDR_LE:
            return None
        (count,) = _U32_LE.unpack_from(raw, 4)
        if count > _MAX_TRANSFORMS:
            return None
        pos = 8
        out = []
        for _ in range(count):
            parent, pos = _string_cdr(raw, ((pos + 3) & ~3) + 8)  # header stamp, frame_id
            child, pos = _string_cdr(raw, pos)
            pos = _align8_cdr(pos)
            x, y, _, qx, qy, qz, qw = _POSE_LE.unpack_from(raw, pos)
            pos += _TRANSFORM
            out.append((parent, child, x, y, qx, qy, qz, qw))
        if not _cdr_complete(raw, pos):
            return None
    except (ValueError, struct.error, UnicodeDecodeError):
        return None
    return out


def tf_ros1(raw: bytes) -> list[TransformFields] | None:
    try:
        (count,) = _U32_LE.unpack_from(raw, 0)
        if count > _MAX_TRANSFORMS:
            return None
        pos = 4
        out = []
        for _ in range(count):
            parent, pos = _string_ros1(raw, pos + 12)  # header seq, sec, nsec
            child, pos = _string_ros1(raw, pos)
            x, y, _, qx, qy, qz, qw = _POSE_LE.unpack_from(raw, pos)
            pos += _TRANSFORM
            out.append((parent, child, x, y, qx, qy, qz, qw))
        if pos != len(raw):
            return None
    except (ValueError, struct.error, UnicodeDecodeError):
        return None
    return out


ODOMETRY: Final[dict[Distro, OdomDecoder]] = {Distro.ROS1: odometry_ros1, Distro.ROS2: odometry_cdr}
TF: Final[dict[Distro, TFDecoder]] = {Distro.ROS1: tf_ros1, Distro.ROS2: tf_cdr}
