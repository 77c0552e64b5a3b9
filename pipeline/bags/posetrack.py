"""Odometry and TF messages → the pose track (``pose_observed`` events), built as columns.

Nearly all converted messages of a robot's bag are odometry and TF, one pose each. Instead of a
Python payload and :class:`Event` per message, the converter collects their raw bytes per
connection while the bag is read (:class:`PoseStream`), and this module turns them into numpy
columns in bulk: decoded by :func:`~objsearch.pipeline.bags.fastdecode.decode_batch` (rosbags'
deserialiser for any other layout), checked, composed with map → odom, and — once the converter
has numbered them among the other derived events — written as the lake's table directly
(:meth:`PoseTrack.table`). :meth:`PoseTrack.events` makes :class:`Event` objects from the same
columns for callers that want events, and ``tests/pipeline/bags/test_bags_posetrack.py`` checks
that the table equals ``events_to_tables`` of those events.

The rules are the per-message ones of ``converter.py``'s module docstring: a message is rejected if
any of its poses has a coordinate that is not finite or farther than :data:`MAX_COORD_M`, or a
quaternion whose norm is not 1 ± 1e-3; a TF message's transforms before the first bad one still
count (they were read before the bad one was met). The scalar rules :func:`coord` and
:func:`rotation_norm` are the definition and give a rejected message its reason; the vector
masks here are the same comparisons on arrays (``test_bags_posetrack.py`` checks them at the
boundaries). Angles go through :mod:`math` element by element, not numpy's vectorised
``arctan2``/``sin``/``cos`` (which may use other, SIMD, implementations), so every number is
bit-for-bit what the per-message arithmetic gives.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Final

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from objsearch.agent.catalogue import STORE
from objsearch.events import Event, EventStoreError, deterministic_event_id
from objsearch.events.arrow import event_schema
from objsearch.pipeline.bags.fastdecode import (
    Decoded,
    LayoutReader,
    OdomFields,
    TransformFields,
    decode_batch,
)
from objsearch.ros.topics import Frames
from objsearch.ros.untrusted import attempt

MAX_COORD_M: Final = 1e5  # a pose or position farther than this from the origin is damage
ROTATION_TOLERANCE: Final = 1e-3
#: A pose that leaves both its neighbours faster than this while they agree with each other is
#: noted as a damaged message: 10x the simulator's robot (0.5 m/s), over 3x a household robot's
#: top speed. Noted, not rejected (a real jump can look the same).
MAX_SPEED_M_S: Final = 5.0
_SPIKE_SLACK_M: Final = 0.01
#: A quaternion whose |norm - 1| is this many times the 90th percentile of its topic's (and at
#: least 1e-12) is not as precise as the topic's other messages: a damaged number.
_PRECISION_RATIO: Final = 1000.0
_MIN_FOR_PRECISION: Final = 10
POSE_TYPE: Final = "pose_observed"
POSE_VERSION: Final = 1

Deserialize = Callable[[bytes, str], Any]
Floats = npt.NDArray[np.float64]
Ints = npt.NDArray[np.int64]
Bools = npt.NDArray[np.bool_]


def coord(v: Any) -> float:
    f = float(v)
    if not math.isfinite(f) or abs(f) > MAX_COORD_M:
        raise ValueError(f"coordinate {f!r} is not plausible")
    return f


def rotation_norm(x: float, y: float, z: float, w: float) -> float:
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not math.isfinite(norm) or abs(norm - 1.0) > ROTATION_TOLERANCE:
        raise ValueError(f"quaternion of norm {norm:.6g} is not a rotation")
    return norm


def _implausible(v: Floats) -> Bools:
    return ~np.isfinite(v) | (np.abs(v) > MAX_COORD_M)  # coord's test


def _not_rotation(x: Floats, y: Floats, z: Floats, w: Floats) -> Bools:
    norm = np.sqrt(x * x + y * y + z * z + w * w)  # rotation_norm's test, same operation order
    return ~np.isfinite(norm) | (np.abs(norm - 1.0) > ROTATION_TOLERANCE)


def _atan2(y: Floats, x: Floats) -> Floats:
    return np.array(list(map(math.atan2, y.tolist(), x.tolist())), dtype=np.float64)


def _yaw(qx: Floats, qy: Floats, qz: Floats, qw: Floats) -> Floats:
    return _atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))


def odometry_fields(msg: Any) -> OdomFields:
    """What :mod:`fastdecode` reads, from a deserialised ``nav_msgs/Odometry``."""
    p = msg.pose.pose
    q = p.orientation
    return (
        msg.header.frame_id,
        float(p.position.x),
        float(p.position.y),
        float(q.x),
        float(q.y),
        float(q.z),
        float(q.w),
    )


def stamp_ns(header: Any) -> int:
    """A deserialised header's stamp in ns (0: none)."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def transform_fields(msg: Any) -> list[TransformFields]:
    """What :mod:`fastdecode` reads, from a deserialised TF message."""
    out = []
    for tr in msg.transforms:
        t, q = tr.transform.translation, tr.transform.rotation
        out.append(
            (
                tr.header.frame_id,
                tr.child_frame_id,
                float(t.x),
                float(t.y),
                float(q.x),
                float(q.y),
                float(q.z),
                float(q.w),
            )
        )
    return out


@dataclass(eq=False)
class PoseStream:
    """One odometry or TF connection's messages, collected as they are read."""

    topic: str
    msgtype: str
    tf: bool  # TF (a list of transforms) rather than odometry
    layout: LayoutReader
    times: list[int] = field(default_factory=list)
    arrivals: list[int] = field(default_factory=list)
    raws: list[bytes] = field(default_factory=list)
    deserialize: Deserialize | None = None

    def add(self, log_ns: int, arrival: int, raw: bytes, deserialize: Deserialize) -> None:
        self.times.append(log_ns)
        self.arrivals.append(arrival)
        # The salvage scanners may hand over memoryviews into buffers they go on using.
        self.raws.append(raw if type(raw) is bytes else bytes(raw))
        self.deserialize = deserialize


@dataclass(frozen=True, slots=True)
class SourceOutcome:
    """What a source's messages gave, for its topic's report row."""

    events: int
    rejected: Counter[str]
    first_ns: int | None  # of the messages accepted
    last_ns: int | None
    #: Accepted poses that look damaged (:func:`suspects`), as report notes: kept.
    suspects: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class Poses:
    """Pose rows before numbering: the keys the converter orders derived events by, and values."""

    time: Ints
    topic: Ints  # code into ``topics``
    arrival: Ints
    index: Ints  # transform index within its message
    from_tf: Bools
    x: Floats
    y: Floats
    yaw: Floats
    frame: Ints  # code into ``frames``
    topics: tuple[str, ...]
    frames: tuple[str, ...]
    stamp: Ints  # the pose's header stamp (0: none)

    def take(self, rows: Ints | Bools) -> Poses:
        return Poses(
            self.time[rows],
            self.topic[rows],
            self.arrival[rows],
            self.index[rows],
            self.from_tf[rows],
            self.x[rows],
            self.y[rows],
            self.yaw[rows],
            self.frame[rows],
            self.topics,
            self.frames,
            self.stamp[rows],
        )


@dataclass(frozen=True, slots=True)
class PoseTrack:
    """Numbered ``pose_observed`` rows in seq order: the table's columns, or events on demand."""

    seq: Ints
    time: Ints
    x: Floats
    y: Floats
    yaw: Floats
    frame: Ints
    topic: Ints
    frames: tuple[str, ...]
    topics: tuple[str, ...]
    #: When the recorder received each pose (``recorded_at_ns``), where ``time`` differs (the
    #: header stamp, or the receive time on the agent's clock:
    #: :mod:`~objsearch.pipeline.bags.clock`); None: the same as ``time``.
    received: Ints | None = None

    def __len__(self) -> int:
        return len(self.seq)

    @property
    def recorded_at(self) -> Ints:
        return self.time if self.received is None else self.received

    def table(self, stream: str) -> pa.Table:
        """The rows as :func:`~objsearch.events.arrow.events_to_tables` would make them."""
        if STORE.upcaster.latest_version(POSE_TYPE) != POSE_VERSION:
            raise EventStoreError(
                f"{POSE_TYPE} has a newer schema than v{POSE_VERSION}: the pose track must "
                "build that version"
            )
        schema = event_schema(POSE_TYPE, STORE)
        n = len(self)
        seqs = self.seq.tolist()
        pose_type = schema.field("pose").type
        columns = [
            pa.array([deterministic_event_id(stream, s) for s in seqs], pa.string()),
            pa.array([stream] * n, pa.string()),
            pa.array(self.seq, pa.int64()),
            pa.array(self.time, pa.int64()),
            pa.array(self.recorded_at, pa.int64()),
            pa.array(np.full(n, POSE_VERSION, dtype=np.int32), pa.int32()),
            pa.nulls(n, pa.string()),
            pa.StructArray.from_arrays(
                [pa.array(self.x), pa.array(self.y), pa.array(self.yaw)],
                fields=[pose_type.field(i) for i in range(pose_type.num_fields)],
            ),
            _strings(self.frame, self.frames),
            _strings(self.topic, self.topics),
        ]
        return pa.Table.from_arrays(columns, schema=schema)

    def events(self, stream: str) -> list[Event]:
        # Event._adopt: the envelope's types are still checked, but no deep copy of a payload
        # built here from checked floats and strings.
        return [
            Event._adopt(
                {
                    "event_id": deterministic_event_id(stream, seq),
                    "stream": stream,
                    "seq": seq,
                    "time_ns": t,
                    "recorded_at_ns": r,
                    "type": POSE_TYPE,
                    "version": POSE_VERSION,
                    "task_id": None,
                    "payload": {
                        "pose": {"x": x, "y": y, "yaw": yaw},
                        "frame_id": self.frames[f],
                        "topic": self.topics[tp],
                    },
                }
            )
            for seq, t, r, x, y, yaw, f, tp in zip(
                self.seq.tolist(),
                self.time.tolist(),
                self.recorded_at.tolist(),
                self.x.tolist(),
                self.y.tolist(),
                self.yaw.tolist(),
                self.frame.tolist(),
                self.topic.tolist(),
                strict=True,
            )
        ]


def _strings(codes: Ints, names: Sequence[str]) -> pa.Array:
    if not len(codes):
        return pa.array([], pa.string())
    dictionary = pa.array(list(names), pa.string())
    return pa.DictionaryArray.from_arrays(pa.array(codes, pa.int32()), dictionary).cast(pa.string())


class _Names:
    """Interned strings: a column of them is an array of codes."""

    def __init__(self) -> None:
        self.codes: dict[str, int] = {}

    def code(self, name: str) -> int:
        return self.codes.setdefault(name, len(self.codes))

    def names(self) -> tuple[str, ...]:
        return tuple(self.codes)


def _reason(exc: Exception) -> str:
    return f"{type(exc).__name__}: {exc}"[:200]


def _message_fields(
    source: PoseStream, deserialize: Deserialize, raw: bytes
) -> tuple[list[TransformFields], list[int]]:
    """One message deserialised by rosbags: its transforms (one for odometry) and their stamps."""
    msg = deserialize(raw, source.msgtype)
    fields: list[TransformFields]
    if source.tf:
        fields = transform_fields(msg)
        stamps = [stamp_ns(tr.header) for tr in msg.transforms]
    else:
        frame, *values = odometry_fields(msg)
        fields = [(frame, "", *values)]  # type: ignore[list-item]
        stamps = [stamp_ns(msg.header)]
    return fields, stamps


def _undecoded_rows(source: PoseStream, decoded: Decoded, rejected: dict[int, str]) -> Decoded:
    """``decoded`` plus the messages it could not read, deserialised by rosbags."""
    if not decoded.undecoded:
        return decoded
    deserialize = source.deserialize
    assert deserialize is not None
    frames = {name: i for i, name in enumerate(decoded.frames)}
    rows: list[tuple[int, int, int, int, int, float, float, float, float, float, float]] = []
    for m in decoded.undecoded:
        read = attempt(partial(_message_fields, source, deserialize, source.raws[m]))
        if isinstance(read, Exception):
            rejected[m] = _reason(read)
            continue
        fields, stamps = read
        for k, (parent, child, *values) in enumerate(fields):
            p = frames.setdefault(parent, len(frames))
            c = frames.setdefault(child, len(frames)) if source.tf else -1
            rows.append((m, k, p, c, stamps[k], *values))  # type: ignore[arg-type]
    if not rows:
        return decoded
    ints = np.array([r[:5] for r in rows], dtype=np.int64).reshape(-1, 5)
    floats = np.array([r[5:] for r in rows], dtype=np.float64).reshape(-1, 6)
    x, y, qx, qy, qz, qw = (
        np.concatenate([old, floats[:, i]]) for i, old in enumerate(_values(decoded))
    )
    return Decoded(
        np.concatenate([decoded.message, ints[:, 0]]),
        np.concatenate([decoded.index, ints[:, 1]]),
        tuple(frames),
        np.concatenate([decoded.parent, ints[:, 2]]),
        np.concatenate([decoded.child, ints[:, 3]]),
        x,
        y,
        qx,
        qy,
        qz,
        qw,
        (),
        np.concatenate([decoded.stamp, ints[:, 4]]),
    )


def _values(d: Decoded) -> tuple[Floats, ...]:
    return d.x, d.y, d.qx, d.qy, d.qz, d.qw


def _first_problem(d: Decoded, row: int) -> str:
    """Why a row failed, from the scalar rules (which define what the masks test)."""
    try:
        coord(d.x[row])
        coord(d.y[row])
        rotation_norm(*(float(v[row]) for v in _values(d)[2:]))
    except ValueError as exc:
        return _reason(exc)
    raise AssertionError(f"row {row} was flagged but passes the scalar rules")  # pragma: no cover


@dataclass
class _Collected:
    poses: list[Poses] = field(default_factory=list)
    #: map → odom transforms: (time, arrival, index, x, y, yaw) columns.
    track: list[tuple[Ints, Ints, Ints, Floats, Floats, Floats]] = field(default_factory=list)


def _convert_source(
    source: PoseStream,
    topic_code: int,
    frames: Frames,
    names: _Names,
    out: _Collected,
) -> SourceOutcome:
    rejected: dict[int, str] = {}
    d = _undecoded_rows(source, decode_batch(source.raws, source.layout, tf=source.tf), rejected)
    n_msgs = len(source.raws)
    times = np.array(source.times, dtype=np.int64)
    arrivals = np.array(source.arrivals, dtype=np.int64)
    with np.errstate(all="ignore"):  # damage makes infinities and NaNs; the masks catch them
        bad = _implausible(d.x) | _implausible(d.y) | _not_rotation(d.qx, d.qy, d.qz, d.qw)
    # A message stops at its first bad pose: the poses before it count, the message is rejected.
    first_bad = np.full(n_msgs, np.iinfo(np.int64).max, dtype=np.int64)
    np.minimum.at(first_bad, d.message[bad], d.index[bad])
    applied = d.index < first_bad[d.message]
    for row in np.flatnonzero(bad & (d.index == first_bad[d.message])).tolist():
        rejected[int(d.message[row])] = _first_problem(d, row)
    accepted = np.ones(n_msgs, dtype=bool)
    accepted[np.array(list(rejected), dtype=np.int64)] = False

    # Frame names as the converter compares them: without a leading "/"; odometry's empty
    # header frame means odom.
    stripped = [f.lstrip("/") for f in d.frames]
    if not source.tf:
        stripped = [f or frames.odom for f in stripped]
    code = np.array([names.code(f) for f in stripped] + [-1], dtype=np.int64)
    parent, child = code[d.parent], code[d.child]  # -1 (no child) maps to the -1 sentinel
    if source.tf:
        track = applied & (parent == names.code(frames.map)) & (child == names.code(frames.odom))
        is_pose = (
            applied
            & ~track
            & (child == names.code(frames.base))
            & ((parent == names.code(frames.odom)) | (parent == names.code(frames.map)))
        )
    else:
        track = np.zeros(len(d.message), dtype=bool)
        is_pose = applied
    used = track | is_pose
    yaw = np.zeros(len(d.message), dtype=np.float64)
    yaw[used] = _yaw(d.qx[used], d.qy[used], d.qz[used], d.qw[used])
    if track.any():
        m = d.message[track]
        out.track.append(
            (times[m], arrivals[m], d.index[track], d.x[track], d.y[track], yaw[track])
        )
    m = d.message[is_pose]
    out.poses.append(
        Poses(
            times[m],
            np.full(len(m), topic_code, dtype=np.int64),
            arrivals[m],
            d.index[is_pose],
            np.full(len(m), source.tf, dtype=bool),
            d.x[is_pose],
            d.y[is_pose],
            yaw[is_pose],
            parent[is_pose],
            (),
            (),
            d.stamp[is_pose],
        )
    )
    kept = times[accepted]
    return SourceOutcome(
        events=int(np.count_nonzero(is_pose & accepted[d.message])),
        rejected=Counter(rejected.values()),
        first_ns=int(kept.min()) if len(kept) else None,
        last_ns=int(kept.max()) if len(kept) else None,
        suspects=tuple(suspects(source.topic, d, is_pose, times)),
    )


def suspects(topic: str, d: Decoded, rows: Bools, received: Ints) -> list[str]:
    """What marks a pose that passed the checks as damaged (a flipped bit), by comparing it with
    the topic's other poses (``rows`` of ``d``, ``received`` per message):

    * its quaternion is unit to a precision far worse than the topic's others (a flipped
      mantissa bit the rotation check's tolerance lets through);
    * its header stamp breaks the order of its neighbours' (which are in order);
    * its position leaves both neighbours faster than :data:`MAX_SPEED_M_S` while they agree.

    A sign flip, or a flip in the low bits of a coordinate, changes none of these.
    """
    order = np.lexsort((d.index[rows], d.message[rows]))  # the order the recorder got them
    x, y, qx, qy, qz, qw, stamp = (
        v[rows][order] for v in (d.x, d.y, d.qx, d.qy, d.qz, d.qw, d.stamp)
    )
    n = len(x)
    notes = []
    with np.errstate(all="ignore"):
        dev = np.abs(np.sqrt(qx * qx + qy * qy + qz * qz + qw * qw) - 1.0)
    if n >= _MIN_FOR_PRECISION:
        usual = float(np.quantile(dev, 0.9))
        odd = dev > max(_PRECISION_RATIO * usual, 1e-12)
        if odd.any():
            notes.append(
                f"{topic}: {int(odd.sum())} pose(s) whose quaternion is unit only to "
                f"{float(dev[odd].max()):.2g} where 90% of the topic's are to {usual:.2g}: a "
                f"damaged number (a flipped bit) within the rotation check's ±{ROTATION_TOLERANCE:g}; "
                "kept"
            )
    if n >= 3:
        before, here, after = stamp[:-2], stamp[1:-1], stamp[2:]
        stamped = (before > 0) & (here > 0) & (after > 0)
        broken = stamped & (before <= after) & ((here < before) | (here > after))
        if broken.any():
            notes.append(
                f"{topic}: {int(broken.sum())} pose(s) whose header stamp breaks the order of "
                "its neighbours': a damaged stamp (a flipped bit), or a publisher out of order; "
                "kept"
            )
        t = np.where(stamp > 0, stamp, received[d.message[rows]][order]).astype(np.float64) / 1e9

        def far(i: slice, j: slice) -> Bools:
            reach = MAX_SPEED_M_S * np.abs(t[j] - t[i]) + _SPIKE_SLACK_M
            return np.asarray(np.hypot(x[j] - x[i], y[j] - y[i]) > reach)

        with np.errstate(all="ignore"):
            spike = (
                far(slice(0, -2), slice(1, -1))
                & far(slice(1, -1), slice(2, None))
                & ~far(slice(0, -2), slice(2, None))
            )
        if spike.any():
            notes.append(
                f"{topic}: {int(spike.sum())} pose(s) that leave both neighbours faster than "
                f"{MAX_SPEED_M_S:g} m/s while those agree: a damaged coordinate (a flipped bit), "
                "or a real jump; kept"
            )
    return notes


def _compose(poses: Poses, collected: _Collected, frames: Frames, names: _Names) -> Poses:
    """Odom-frame poses in the map frame with map → odom as of their time (or the first one
    known, for poses recorded before it): localisation publishes asynchronously."""
    if not collected.track:
        return poses
    t_time, t_arrival, t_index, t_x, t_y, t_yaw = (
        np.concatenate(c) for c in zip(*collected.track, strict=True)
    )
    order = np.lexsort((t_index, t_arrival, t_time))  # by time, ties in the order they came
    t_time, t_x, t_y, t_yaw = t_time[order], t_x[order], t_y[order], t_yaw[order]
    in_odom = poses.frame == names.code(frames.odom)
    i = np.maximum(np.searchsorted(t_time, poses.time[in_odom], side="right") - 1, 0)
    yaw_list = t_yaw.tolist()
    c = np.array(list(map(math.cos, yaw_list)))[i]
    s = np.array(list(map(math.sin, yaw_list)))[i]
    px, py = poses.x[in_odom], poses.y[in_odom]
    x, y, yaw = poses.x.copy(), poses.y.copy(), poses.yaw.copy()
    x[in_odom] = t_x[i] + c * px - s * py
    y[in_odom] = t_y[i] + s * px + c * py
    turned = (t_yaw[i] + poses.yaw[in_odom]).tolist()
    yaw[in_odom] = _atan2(
        np.array(list(map(math.sin, turned)), dtype=np.float64),
        np.array(list(map(math.cos, turned)), dtype=np.float64),
    )
    frame = poses.frame.copy()
    frame[in_odom] = names.code(frames.map)
    return Poses(
        poses.time,
        poses.topic,
        poses.arrival,
        poses.index,
        poses.from_tf,
        x,
        y,
        yaw,
        frame,
        poses.topics,
        names.names(),
        poses.stamp,
    )


def convert_sources(
    sources: Sequence[PoseStream], frames: Frames
) -> tuple[Poses, list[SourceOutcome]]:
    """All sources' poses (in no particular order; the converter numbers them) and outcomes."""
    topics = _Names()
    names = _Names()
    collected = _Collected()
    outcomes = [_convert_source(s, topics.code(s.topic), frames, names, collected) for s in sources]
    parts = collected.poses

    def cat(name: str, dtype: type[np.generic]) -> Any:
        return np.concatenate([getattr(p, name) for p in parts]) if parts else np.zeros(0, dtype)

    poses = Poses(
        cat("time", np.int64),
        cat("topic", np.int64),
        cat("arrival", np.int64),
        cat("index", np.int64),
        cat("from_tf", np.bool_),
        cat("x", np.float64),
        cat("y", np.float64),
        cat("yaw", np.float64),
        cat("frame", np.int64),
        topics.names(),
        names.names(),
        cat("stamp", np.int64),
    )
    return _compose(poses, collected, frames, names), outcomes
