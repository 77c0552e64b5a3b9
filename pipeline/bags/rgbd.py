"""A bag's RGB-D views → the semantic map: depth, instance image, label table, camera info, TF.

What a view needs, by topic role (``topics.py``; the defaults are what ``objsearch record
--mapping-sweep`` writes and a RealSense-style driver plus a segmentation node publish):

* ``depth``: ``sensor_msgs/Image`` ``32FC1`` in metres (REP 118; NaN/inf = no return) or
  ``16UC1`` in millimetres (0 = no return), registered to the camera of the camera info;
* ``instances``: ``sensor_msgs/Image`` ``mono16``/``16UC1`` (or 8-bit): pixel value k > 0 is the
  k-th detection of the ``detections`` array with the same header stamp, 0 is none;
* ``detections``: ``vision_msgs/Detection2DArray``: each detection's best hypothesis gives the
  mask's class and score;
* ``camera_info``: K of a pinhole (distortion is not undone; a note says so when D ≠ 0);
* ``tf`` / ``tf_static``: map → … → the images' ``frame_id`` at the images' stamp
  (:class:`~objsearch.ros.tf.TransformBuffer`, interpolated, never extrapolated).

Parts of a view are matched by header stamp. A view waits until TF has reached its stamp (as a
tf2 message filter does), at most :data:`MAX_PENDING` views at a time, so memory stays bounded.
Each complete view becomes a :class:`~objsearch.agent.mapping.MaskedDepth` and goes to the same
``SemanticMapBuilder.add`` the simulator's views go to. RGB is counted, not read: the recorded
masks stand for a detector's output.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from objsearch.agent.camera_frames import CameraIntrinsics, FloatArray
from objsearch.agent.detect import MaskDetection
from objsearch.agent.mapping import BuiltMap, MappingConfig, MaskedDepth, SemanticMapBuilder
from objsearch.agent.navmap import NavigationMap
from objsearch.pipeline.bags.detections import hypothesis_score
from objsearch.pipeline.bags.errors import BagError
from objsearch.pipeline.bags.formats import detect
from objsearch.pipeline.bags.losses import unrecovered
from objsearch.pipeline.bags.readers import read_messages
from objsearch.pipeline.bags.salvage import Loss, RawConnection
from objsearch.pipeline.bags.sink import Deserialize
from objsearch.ros.errors import TransformError
from objsearch.ros.images import ImageError, decode_image, depth_metres, intrinsics_of
from objsearch.ros.tf import TransformBuffer
from objsearch.ros.topics import ACCEPTED_TYPES, Role, TopicMap
from objsearch.ros.untrusted import attempt

#: Views held while waiting for TF or a missing part; the oldest is dropped beyond this.
MAX_PENDING: Final = 32
IMAGE: Final = "sensor_msgs/msg/Image"
READ: Final = {
    Role.DEPTH: frozenset({IMAGE}),
    Role.INSTANCES: frozenset({IMAGE}),
    Role.DETECTIONS: ACCEPTED_TYPES[Role.DETECTIONS],
    Role.CAMERA_INFO: ACCEPTED_TYPES[Role.CAMERA_INFO],
    Role.TF: ACCEPTED_TYPES[Role.TF],
    Role.TF_STATIC: ACCEPTED_TYPES[Role.TF_STATIC],
}
_WHAT = {
    Role.DEPTH: "depth images",
    Role.INSTANCES: "instance images",
    Role.DETECTIONS: "detections (the instance images' label table)",
    Role.CAMERA_INFO: "camera info",
}


def _stamp(header: Any) -> int:
    return int(header.stamp.sec) * 10**9 + int(header.stamp.nanosec)


def _best(d: Any) -> tuple[str, float]:
    """Class and score of a detection's best hypothesis (ROS 2 4.x or ROS 1 layout)."""
    best = max(d.results, key=hypothesis_score, default=None)
    if best is None:
        return "", 0.0
    hyp = getattr(best, "hypothesis", best)
    return str(getattr(hyp, "class_id", getattr(hyp, "id", ""))), float(hyp.score)


@dataclass
class _Pending:
    frame_id: str = ""
    depth: FloatArray | None = None
    instances: npt.NDArray[Any] | None = None
    table: list[tuple[str, float, str]] | None = None  # (class, score, instance id) per detection

    def missing(self) -> list[str]:
        parts = [
            (self.depth, "depth"),
            (self.instances, "instance image"),
            (self.table, "detections"),
        ]
        return [name for value, name in parts if value is None]


@dataclass(frozen=True, slots=True)
class ViewReport:
    path: str
    format: str
    reader: str
    views: int
    messages: dict[str, int]  # per topic
    skipped: dict[str, int]  # views not fused, per reason
    rejected: dict[str, int]  # messages that did not decode, per reason
    losses: tuple[Loss, ...]
    notes: tuple[str, ...]

    def render(self) -> str:
        lines = [f"{self.path} ({self.format}, read by {self.reader}): {self.views} views fused"]
        lines += [f"  {t:32} {n:8} msgs" for t, n in sorted(self.messages.items())]
        lines += [f"  skipped {n} view(s): {why}" for why, n in sorted(self.skipped.items())]
        lines += [f"  rejected {n} message(s): {why}" for why, n in sorted(self.rejected.items())]
        lines += [f"  LOST {loss}" for loss in self.losses]
        lines += [f"  note: {note}" for note in self.notes]
        return "\n".join(lines)


@dataclass
class ViewCollector:
    """A :class:`~objsearch.pipeline.bags.sink.MessageSink` that assembles views and hands each
    complete one to ``on_view``."""

    topic_map: TopicMap
    on_view: Callable[[MaskedDepth], None]
    tf: TransformBuffer = field(default_factory=TransformBuffer)
    conns: dict[int, tuple[RawConnection, Role]] = field(default_factory=dict)
    ignored: dict[int, tuple[RawConnection, str]] = field(default_factory=dict)
    counts: Counter[str] = field(default_factory=Counter)
    received: Counter[Role] = field(default_factory=Counter)
    infos: dict[int, CameraIntrinsics] = field(default_factory=dict)
    pending: dict[int, _Pending] = field(default_factory=dict)
    views: int = 0
    skipped: Counter[str] = field(default_factory=Counter)
    rejected: Counter[str] = field(default_factory=Counter)
    notes: set[str] = field(default_factory=set)

    # -- MessageSink ------------------------------------------------------------------------------

    def plan(
        self, conns: Iterable[RawConnection], known: Callable[[RawConnection], str | None]
    ) -> None:
        for c in conns:
            if c.id in self.conns or c.id in self.ignored:
                continue
            role = self.topic_map.role(c.topic)
            if role not in READ:
                self.ignored[c.id] = (c, "not read for mapping")
            elif c.msgtype not in READ[role]:
                self.ignored[c.id] = (c, f"{c.msgtype} is not read as {role.value}")
            elif (why := known(c)) is not None:
                self.ignored[c.id] = (c, why)
            else:
                self.conns[c.id] = (c, role)

    def wants(self, conn_id: int) -> bool:
        return conn_id in self.conns

    def count(self, conn_id: int, n: int = 1) -> None:
        entry = self.conns.get(conn_id) or self.ignored.get(conn_id)
        if entry is not None:
            self.counts[entry[0].topic] += n

    def messages_per_topic(self) -> Counter[str]:
        return Counter(self.counts)

    def end_of_messages(self) -> None:
        pass  # views are collected as they come

    def feed(self, conn_id: int, log_ns: int, raw: bytes, deserialize: Deserialize) -> None:
        entry = self.conns.get(conn_id)
        if entry is None:
            self.count(conn_id)
            return
        conn, role = entry
        self.counts[conn.topic] += 1
        taken = attempt(lambda: self._take(role, deserialize(raw, conn.msgtype)))
        if isinstance(taken, Exception):
            self.rejected[f"{conn.topic}: {type(taken).__name__}: {taken}"[:200]] += 1
            return
        self.received[role] += 1
        self._flush(final=False)

    # -- assembling views -------------------------------------------------------------------------

    def _take(self, role: Role, msg: Any) -> None:
        if role in (Role.TF, Role.TF_STATIC):
            for tr in msg.transforms:
                t, q = tr.transform.translation, tr.transform.rotation
                self.tf.add(
                    tr.header.frame_id.lstrip("/"),
                    tr.child_frame_id.lstrip("/"),
                    _stamp(tr.header),
                    np.array([t.x, t.y, t.z], dtype=np.float64),
                    np.array([q.x, q.y, q.z, q.w], dtype=np.float64),
                    static=role is Role.TF_STATIC,
                )
            return
        stamp = _stamp(msg.header)
        if role is Role.CAMERA_INFO:
            intr, distorted = intrinsics_of(msg)
            if distorted:
                self.notes.add("camera info declares distortion; images are used as pinhole")
            self.infos[stamp] = intr
            return
        view = self.pending.setdefault(stamp, _Pending())
        if role is Role.DETECTIONS:
            view.table = [(*_best(d), str(d.id)) for d in msg.detections]
        elif role is Role.DEPTH:
            view.depth, view.frame_id = depth_metres(msg), msg.header.frame_id.lstrip("/")
        elif role is Role.INSTANCES:
            pixels = decode_image(msg)
            if pixels.ndim != 2:
                raise ImageError(f"instance image must have one channel, not {msg.encoding}")
            view.instances = pixels
        if len(self.pending) > MAX_PENDING:
            oldest = min(self.pending)
            self._skip(self.pending.pop(oldest))

    def _skip(self, view: _Pending, why: str | None = None) -> None:
        if view.depth is None and view.instances is None:
            return  # detections without images (a search's): not a view at all
        self.skipped[why or "incomplete: no " + ", no ".join(view.missing())] += 1

    def _intrinsics(self, stamp: int, final: bool) -> CameraIntrinsics | None:
        if stamp in self.infos:
            return self.infos[stamp]
        earlier = [s for s in self.infos if s <= stamp]
        if earlier:
            return self.infos[max(earlier)]
        return self.infos[min(self.infos)] if final and self.infos else None

    def _flush(self, *, final: bool) -> None:
        for stamp in sorted(self.pending):
            view = self.pending[stamp]
            if view.missing():
                if final:
                    self._skip(self.pending.pop(stamp))
                continue
            if not final and (self.tf.latest_ns is None or self.tf.latest_ns < stamp):
                continue  # TF may still reach this stamp
            intr = self._intrinsics(stamp, final)
            if intr is None:
                if final:
                    self._skip(self.pending.pop(stamp), "no camera info")
                continue
            try:
                pose = self.tf.lookup(self.topic_map.frames.map, view.frame_id, stamp)
            except TransformError as exc:
                if final or "after the last" not in str(exc):
                    self._skip(self.pending.pop(stamp), f"TF: {exc}")
                continue
            del self.pending[stamp]
            try:
                made = self._view(stamp, view, intr, pose)
            except ValueError as exc:
                self._skip(view, str(exc))
                continue
            self.on_view(made)
            self.views += 1

    def _view(
        self, stamp: int, view: _Pending, intr: CameraIntrinsics, pose: npt.NDArray[np.float64]
    ) -> MaskedDepth:
        assert view.depth is not None and view.instances is not None and view.table is not None
        if view.depth.shape != intr.shape or view.instances.shape != intr.shape:
            raise ValueError(
                f"image sizes {view.depth.shape[::-1]} (depth), {view.instances.shape[::-1]} "
                f"(instances) differ from the camera info's {intr.width}×{intr.height}"
            )
        values = np.unique(view.instances)
        values = values[values > 0]
        if len(values) and int(values[-1]) > len(view.table):
            raise ValueError(
                f"instance value {int(values[-1])} but only {len(view.table)} detections"
            )
        detections = tuple(
            MaskDetection(cls, view.instances == v, score, ident)
            for v in values
            for cls, score, ident in (view.table[int(v) - 1],)
        )
        return MaskedDepth(view.depth, intr, pose, detections, stamp)

    def finish(self) -> None:
        self._flush(final=True)

    def missing(self) -> list[str]:
        """What the bag lacks for mapping, named with the topics it was looked for on."""
        out = []
        for role, what in _WHAT.items():
            if not self.received[role]:
                out.append(f"no {what} ({self._where(role)})")
        if not (self.received[Role.TF] or self.received[Role.TF_STATIC]):
            out.append(f"no TF ({self._where(Role.TF)}; {self._where(Role.TF_STATIC)})")
        return out

    def _where(self, role: Role) -> str:
        topics = [t for t, r in self.topic_map.topics.items() if r is role]
        why = [
            f"{c.topic}: {reason}"
            for c, reason in self.ignored.values()
            if self.topic_map.role(c.topic) is role
        ]
        types = " or ".join(sorted(t.rsplit("/", 1)[-1] for t in READ[role]))
        return f"{types} on {' or '.join(topics) or 'no mapped topic'}" + (
            f"; {'; '.join(why)}" if why else ""
        )


def build_map_from_bag(
    path: Path,
    navmap: NavigationMap,
    classes: Sequence[str],
    config: MappingConfig | None = None,
    *,
    topic_map: TopicMap | None = None,
    device: Any = None,
    progress: bool = False,
) -> tuple[BuiltMap, ViewReport]:
    """The semantic map of a bag's views, fused by the simulator path's ``SemanticMapBuilder``.

    A bag that ``AnyReader`` cannot read to the end is read again by the salvage scanners into a
    fresh builder; the map is then built from what they recovered and the report says what was
    lost. Raises :class:`BagError` naming what is missing when no view can be built.
    """
    path = Path(path)
    topic_map = topic_map or TopicMap()
    fmt = detect(path)
    builders: list[SemanticMapBuilder] = []

    def make() -> ViewCollector:
        builders.append(SemanticMapBuilder(navmap, classes, config, device=device))
        return ViewCollector(topic_map, builders[-1].add)

    sink, outcome = read_messages(path, fmt, make, progress=progress)
    sink.finish()
    losses = (*outcome.losses, *unrecovered(outcome, sink))
    if sink.views == 0:
        problems = sink.missing() or [
            f"{n} view(s) skipped: {why}" for why, n in sorted(sink.skipped.items())
        ]
        if sink.rejected:
            problems += [f"{n} message(s) rejected: {why}" for why, n in sink.rejected.items()]
        if losses:
            problems.append(f"the bag is damaged ({outcome.reader}): {losses[0]}")
        raise BagError(f"{path}: cannot build a map, " + "; ".join(problems or ["no views"]))
    report = ViewReport(
        path=str(path),
        format=fmt.value,
        reader=outcome.reader,
        views=sink.views,
        messages=dict(sink.counts),
        skipped=dict(sink.skipped),
        rejected=dict(sink.rejected),
        losses=losses,
        notes=(*outcome.notes, *sorted(sink.notes)),
    )
    return builders[-1].build(), report
