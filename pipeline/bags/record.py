"""``objsearch record``: simulated searches written as the robot would record them.

The searches run exactly as ``objsearch demo`` runs them (one event log, one scene graph); a
:class:`~objsearch.sim.world.WorldObserver` collects every pose and camera frame. The bag then
holds, stamped on one clock (``start_ns`` + the simulated clock):

* ``/tf_static``: base_link → camera_link, once;
* ``/odom`` (``nav_msgs/Odometry``, odom → base_link) at ``odom_hz`` and at every pose change,
  with ``/tf`` carrying map → odom and odom → base_link at the same stamps;
* ``/camera/color/camera_info`` and ``/objsearch/detections`` (``vision_msgs/Detection2DArray``)
  for every camera frame the simulator rendered;
* ``/objsearch/events`` (``objsearch_msgs/Event``): every event of the agent's log.

``record_mapping_sweep`` writes the §4.3 mapping survey instead: the robot holds still at each
view (sampling points on each room's boundary, a view every 45°) while the camera publishes RGB
(``rgb8``), depth (``32FC1``, metres, REP 118), an instance image (``mono16``: pixel value k is the
k-th detection of the ``Detection2DArray`` with the same stamp, 0 none) and camera info, all in
the optical frame, with ``/tf_static`` carrying base_link → camera_link → camera_link_optical.

The simulator's map and odom frames coincide (no drift), so map → odom is the identity.
"""

from __future__ import annotations

import bisect
import math
import shutil
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

from objsearch.agent.camera_frames import CameraIntrinsics
from objsearch.agent.catalogue import STORE
from objsearch.agent.geometry import Pose
from objsearch.agent.world import Detection
from objsearch.events import Event, read_log
from objsearch.pipeline.bags.errors import BagError
from objsearch.pipeline.bags.formats import BagFormat
from objsearch.ros import bagqos
from objsearch.ros.builder import BoxCamera, MessageBuilder
from objsearch.ros.topics import Role, TopicMap
from objsearch.ros.types import Distro, typestore
from objsearch.sim.perception import IMAGE_HEIGHT, IMAGE_WIDTH, Camera
from objsearch.sim.world import DEFAULT_CAMERA

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt
    from rosbags.interfaces import Qos

    from objsearch.agent.camera_frames import RGBDFrame
    from objsearch.agent.detect import Detector, MaskDetection
    from objsearch.sim.render import SimulatedCamera

#: Sweep timing: a view every 2 s; the robot holds still for the first second and the images are
#: stamped 0.55 s in, off the 10 Hz TF grid, so a reader must interpolate TF (as with a real camera).
SWEEP_VIEW_NS = 2_000_000_000
SWEEP_HOLD_NS = 1_000_000_000
SWEEP_IMAGE_NS = 550_000_000

#: 2026-01-01T00:00:00Z: the bag clock of a recording starts here unless told otherwise, so two
#: recordings of the same run are identical.
DEFAULT_START_NS = 1_767_225_600 * 10**9
DEFAULT_ODOM_HZ = 10.0

MSG_TYPES = {
    Role.ODOMETRY: "nav_msgs/msg/Odometry",
    Role.TF: "tf2_msgs/msg/TFMessage",
    Role.TF_STATIC: "tf2_msgs/msg/TFMessage",
    Role.CAMERA_INFO: "sensor_msgs/msg/CameraInfo",
    Role.IMAGE: "sensor_msgs/msg/Image",
    Role.DEPTH: "sensor_msgs/msg/Image",
    Role.INSTANCES: "sensor_msgs/msg/Image",
    Role.DETECTIONS: "vision_msgs/msg/Detection2DArray",
    Role.EVENTS: "objsearch_msgs/msg/Event",
}


#: The QoS each topic's publisher offers on a ROS 2 robot (recorded as rosbag2 does, so that
#: ``ros2 bag play`` latches /tf_static): camera topics reliable like the rest (a reliable offer
#: serves best-effort subscribers too).
ROLE_QOS: dict[Role, Qos] = {
    Role.ODOMETRY: bagqos.DEFAULT,
    Role.TF: bagqos.TF,
    Role.TF_STATIC: bagqos.TF_STATIC,
    Role.CAMERA_INFO: bagqos.DEFAULT,
    Role.IMAGE: bagqos.DEFAULT,
    Role.DEPTH: bagqos.DEFAULT,
    Role.INSTANCES: bagqos.DEFAULT,
    Role.DETECTIONS: bagqos.DEFAULT,
    Role.EVENTS: bagqos.EVENTS,
}


@dataclass
class Timeline:
    """What the simulated sensors saw, in simulated time: a :class:`WorldObserver`."""

    poses: list[tuple[int, Pose]] = field(default_factory=list)
    frames: list[tuple[int, Pose, tuple[Detection, ...]]] = field(default_factory=list)

    def pose_changed(self, time_ns: int, pose: Pose) -> None:
        self.poses.append((time_ns, pose))

    def camera_frame(self, time_ns: int, pose: Pose, detections: Sequence[Detection]) -> None:
        self.frames.append((time_ns, pose, tuple(detections)))

    def samples(self, hz: float) -> list[tuple[int, Pose]]:
        """Every recorded pose plus poses interpolated at ``hz`` in between, in time order."""
        if not self.poses:
            return []
        out = list(self.poses)
        if hz > 0:
            period = round(1e9 / hz)
            times = [t for t, _ in self.poses]
            t = times[0] - times[0] % period + period
            while t < times[-1]:
                i = bisect.bisect_right(times, t) - 1
                (t0, a), (t1, b) = self.poses[i], self.poses[i + 1]
                if t1 > t0 and t not in (t0, t1):
                    out.append((t, _interpolate(a, b, (t - t0) / (t1 - t0))))
                t += period
        out.sort(key=lambda tp: tp[0])  # stable: equal stamps keep the order they happened in
        return out


def _interpolate(a: Pose, b: Pose, f: float) -> Pose:
    # The simulator turns to the heading of a step when it starts it; yaw follows b.
    return Pose(a.x + (b.x - a.x) * f, a.y + (b.y - a.y) * f, b.yaw)


@dataclass(frozen=True, slots=True)
class Recording:
    path: Path
    format: BagFormat
    messages: dict[str, int]
    events: int
    tasks: int
    start_ns: int
    end_ns: int


def box_camera(camera: Camera) -> BoxCamera:
    """The simulator's camera as the pinhole the detection boxes are drawn in."""
    return BoxCamera(camera.focal_px, camera.height, IMAGE_WIDTH, IMAGE_HEIGHT)


def bag_messages(
    timeline: Timeline,
    events: Sequence[Event],
    distro: Distro,
    topic_map: TopicMap,
    *,
    start_ns: int = DEFAULT_START_NS,
    odom_hz: float = DEFAULT_ODOM_HZ,
    camera: Camera | None = None,
) -> _Schedule:
    """(bag time, role, message) for everything the robot publishes, in time order (an
    iterable whose ``len`` is the number of messages)."""
    camera = camera or Camera()
    m = MessageBuilder(distro, topic_map, box_camera(camera))
    f = camera.focal_px
    # The geometric camera model's image centre, as sim/perception.py projects with it.
    k = CameraIntrinsics(IMAGE_WIDTH, IMAGE_HEIGHT, f, f, IMAGE_WIDTH / 2, IMAGE_HEIGHT / 2)
    out = _Schedule(start_ns)
    first = min([t for t, _ in timeline.poses[:1]] + [e.time_ns for e in events[:1]], default=0)
    out.add(first, Role.TF_STATIC, lambda: m.tf_static(start_ns + first, camera.height))
    out.add_motion(m, timeline, odom_hz)
    for t, pose, dets in timeline.frames:
        stamp = start_ns + t
        out.add(t, Role.CAMERA_INFO, partial(m.camera_info, stamp, k, m.frames.camera))
        out.add(t, Role.DETECTIONS, partial(m.detections, stamp, pose, dets))
    for e in events:
        out.add(e.time_ns, Role.EVENTS, partial(m.event, start_ns + e.time_ns, e))
    return out


class _Schedule:
    """Messages to write, made lazily (images are large) and yielded in (stamp, order added)."""

    def __init__(self, start_ns: int) -> None:
        self.start_ns = start_ns
        self.items: list[tuple[int, int, Role, Callable[[], Any]]] = []

    def add(self, sim_ns: int, role: Role, make: Callable[[], Any]) -> None:
        self.items.append((self.start_ns + sim_ns, len(self.items), role, make))

    def add_motion(self, m: MessageBuilder, timeline: Timeline, odom_hz: float) -> None:
        """Odometry and TF at every pose change and at ``odom_hz`` in between."""
        previous: tuple[int, Pose] | None = None
        for t, pose in timeline.samples(odom_hz):
            twist = (0.0, 0.0)
            if previous is not None and t > previous[0]:
                dt = (t - previous[0]) / 1e9
                twist = (math.dist(pose[:2], previous[1][:2]) / dt, 0.0)
            previous = (t, pose)
            stamp = self.start_ns + t
            self.add(t, Role.ODOMETRY, partial(m.odometry, stamp, pose, twist))
            self.add(t, Role.TF, partial(m.tf, stamp, pose))

    def __len__(self) -> int:
        return len(self.items)

    def __iter__(self) -> Iterator[tuple[int, Role, Any]]:
        self.items.sort(key=lambda item: (item[0], item[1]))
        for stamp, _, role, make in self.items:
            yield stamp, role, make()


def sweep_messages(
    camera: SimulatedCamera,
    poses: Sequence[tuple[str, Pose]],
    detector: Detector,
    distro: Distro,
    topic_map: TopicMap,
    *,
    start_ns: int = DEFAULT_START_NS,
    odom_hz: float = DEFAULT_ODOM_HZ,
) -> _Schedule:
    """(bag time, role, message) of a mapping sweep: one rendered view per (room, pose)."""
    m = MessageBuilder(distro, topic_map)
    timeline = Timeline()
    for i, (_, pose) in enumerate(poses):
        timeline.pose_changed(i * SWEEP_VIEW_NS, pose)
        timeline.pose_changed(i * SWEEP_VIEW_NS + SWEEP_HOLD_NS, pose)
    out = _Schedule(start_ns)
    out.add(
        0,
        Role.TF_STATIC,
        lambda: m.tf_static(start_ns, camera.height, pitch=camera.pitch, optical=True),
    )
    out.add_motion(m, timeline, odom_hz)
    views = _Views(camera, poses, detector, start_ns)
    optical = m.frames.camera_optical
    for i in range(len(poses)):
        t = i * SWEEP_VIEW_NS + SWEEP_IMAGE_NS
        stamp = start_ns + t
        out.add(t, Role.CAMERA_INFO, partial(m.camera_info, stamp, camera.intrinsics, optical))
        for role in (Role.IMAGE, Role.DEPTH, Role.INSTANCES):
            out.add(t, role, partial(views.image, m, stamp, i, role))
        out.add(t, Role.DETECTIONS, partial(views.detections, m, stamp, i))
    return out


class _Views:
    """Renders each sweep view once, when its first message is made (one view held at a time)."""

    def __init__(
        self,
        camera: SimulatedCamera,
        poses: Sequence[tuple[str, Pose]],
        detector: Detector,
        start_ns: int,
    ) -> None:
        self.camera, self.poses, self.detector, self.start_ns = camera, poses, detector, start_ns
        self._held: tuple[int, RGBDFrame, tuple[MaskDetection, ...]] | None = None

    def _view(self, i: int) -> tuple[RGBDFrame, tuple[MaskDetection, ...]]:
        if self._held is None or self._held[0] != i:
            room, pose = self.poses[i]
            stamp = self.start_ns + i * SWEEP_VIEW_NS + SWEEP_IMAGE_NS
            frame = self.camera.frame(pose, room, stamp_ns=stamp)
            self._held = (i, frame, self.detector.detect(frame))
        return self._held[1], self._held[2]

    def image(self, m: MessageBuilder, stamp: int, i: int, role: Role) -> Any:
        """RGB ``rgb8``, depth ``32FC1`` (metres, REP 118) or the instance image ``mono16``."""
        frame = self._view(i)[0]
        if role is Role.IMAGE:
            return m.image(stamp, "rgb8", frame.rgb)
        if role is Role.DEPTH:
            return m.image(stamp, "32FC1", frame.depth)
        return m.image(stamp, "mono16", self._instances(i))

    def detections(self, m: MessageBuilder, stamp: int, i: int) -> Any:
        """The instance image's label table: detection k is pixel value k + 1."""
        return m.detection_array(stamp, m.frames.camera_optical, self._table(i))

    def _instances(self, i: int) -> npt.NDArray[np.uint16]:
        """Pixel value k + 1 for the k-th detection; overlaps go to the higher score, as
        ``agent.mapping.label_image`` resolves them."""
        import numpy as np

        frame, dets = self._view(i)
        image = np.zeros(frame.intrinsics.shape, dtype=np.uint16)
        for k in sorted(range(len(dets)), key=lambda k: dets[k].score):
            image[dets[k].mask] = k + 1
        return image

    def _table(
        self, i: int
    ) -> list[
        tuple[str, str, float, tuple[float, float, float, float], tuple[float, float, float]]
    ]:
        import numpy as np

        from objsearch.agent.detect import locate

        frame, dets = self._view(i)
        rows = []
        for k, d in enumerate(dets):
            rs, cs = np.nonzero(d.mask)
            box = (
                (cs.min() + cs.max()) / 2,
                (rs.min() + rs.max()) / 2,
                cs.max() - cs.min() + 1,
                rs.max() - rs.min() + 1,
            )
            # A rendered object's pixels always have depth (beyond range they show no object).
            position = locate(frame, d)
            assert position is not None
            rows.append(
                (
                    d.instance_id or f"{d.cls}#{k + 1}",
                    d.cls,
                    d.score,
                    tuple(map(float, box)),
                    position,
                )
            )
        return rows  # type: ignore[return-value]


def write_bag(
    path: Path,
    fmt: BagFormat,
    messages: Iterable[tuple[int, Role, Any]],
    topic_map: TopicMap,
    *,
    chunk_bytes: int | None = None,
    compress: bool = True,
    progress: Callable[[int], None] | None = None,
) -> dict[str, int]:
    """Write ``messages`` with the rosbags writer of ``fmt``; returns messages per topic.

    Written into a temporary sibling and renamed into place, so ``path`` never holds half a bag.
    ``chunk_bytes`` sets the chunk size of ROS 1 and MCAP bags (1 MiB). An MCAP bag has zstd
    chunks and CRCs unless ``compress`` is false (:mod:`~objsearch.ros.mcapstore`).
    ROS 1 connections store the full ``.msg`` text of their types (:mod:`.ros1defs`), ROS 2 ones
    the QoS the robot's publishers offer (:data:`ROLE_QOS`). ``progress`` is called with the
    number of messages written so far, every 10 000 and at the end.
    """
    from objsearch.pipeline.bags.ros1defs import full_definition

    if path.exists():
        raise BagError(f"{path} already exists; choose a new --out (bags are never overwritten)")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp_root = Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=path.parent))
    tmp = tmp_root / path.name
    counts: dict[str, int] = {}
    written = 0
    store = typestore(fmt.distro)
    try:
        if fmt is BagFormat.ROS1:
            from rosbags.rosbag1 import Writer as Writer1

            w1 = Writer1(tmp)
            if chunk_bytes is not None:
                w1.chunk_threshold = chunk_bytes
            with w1:
                conns1: dict[Role, Any] = {}
                for stamp, role, msg in messages:
                    msgtype = MSG_TYPES[role]
                    if role not in conns1:
                        msgdef, md5sum = store.generate_msgdef(msgtype)
                        conns1[role] = w1.add_connection(
                            topic_map.topic_for(role),
                            msgtype,
                            msgdef=full_definition(store, msgtype) or msgdef,
                            md5sum=md5sum,
                            latching=1 if role is Role.TF_STATIC else None,
                        )
                    w1.write(conns1[role], stamp, bytes(store.serialize_ros1(msg, msgtype)))
                    topic = topic_map.topic_for(role)
                    counts[topic] = counts.get(topic, 0) + 1
                    written += 1
                    if progress is not None and written % 10_000 == 0:
                        progress(written)
        else:
            from rosbags.rosbag2 import StoragePlugin

            from objsearch.ros.mcapstore import rosbag2_writer

            plugin = StoragePlugin.MCAP if fmt is BagFormat.ROS2_MCAP else StoragePlugin.SQLITE3
            with rosbag2_writer(tmp, plugin, compress=compress, chunk_bytes=chunk_bytes) as w2:
                conns2: dict[Role, Any] = {}
                for stamp, role, msg in messages:
                    msgtype = MSG_TYPES[role]
                    if role not in conns2:
                        conns2[role] = w2.add_connection(
                            topic_map.topic_for(role),
                            msgtype,
                            typestore=store,
                            offered_qos_profiles=[ROLE_QOS[role]],
                        )
                    w2.write(conns2[role], stamp, bytes(store.serialize_cdr(msg, msgtype)))
                    topic = topic_map.topic_for(role)
                    counts[topic] = counts.get(topic, 0) + 1
                    written += 1
                    if progress is not None and written % 10_000 == 0:
                        progress(written)
        tmp.rename(path)
    finally:
        shutil.rmtree(tmp_root, ignore_errors=True)
    if progress is not None:
        progress(written)
    return counts


def _check_out(out: Path, fmt: BagFormat) -> None:
    if fmt is BagFormat.ROS1 and out.suffix != ".bag":
        raise BagError(f"a ROS 1 bag is one file named *.bag; got --out {out}")
    if fmt is not BagFormat.ROS1 and out.suffix in (".bag", ".db3", ".mcap"):
        raise BagError(f"a ROS 2 bag is a directory; give --out a directory name, not {out.name}")
    if out.exists():
        raise BagError(f"{out} already exists; choose a new --out (bags are never overwritten)")


#: ``progress(stage, done, total)`` of :func:`record`.
Progress = Callable[[str, int, int], None]

#: Bytes a search of the paper home's schedule takes in each format, measured on the full
#: schedule (640 searches; docs/pipeline.md, "Compression"): ``objsearch record`` says up front
#: how large a recording will be.
BYTES_PER_SEARCH: dict[tuple[BagFormat, bool], int] = {
    (BagFormat.ROS2_MCAP, True): 94_039,  # 60.2 MB for 640 searches, zstd
    (BagFormat.ROS2_MCAP, False): 1_313_026,  # 840.3 MB, --no-compress
    (BagFormat.ROS1, False): 1_312_833,  # 840.2 MB (ROS 1 bags are not compressed)
}


def planned_searches(
    home: str,
    *,
    scenes: Sequence[int] | None = None,
    targets: Sequence[str] | None = None,
    starts: Sequence[str] | None = None,
    schedule: str = "table2",
) -> int:
    """How many searches :func:`record` runs for these choices (all of each by default)."""
    from objsearch.agent.session import load_context
    from objsearch.sim.longterm import TARGET_ORDER
    from objsearch.sim.schedule_names import load_schedule

    ctx = load_context(home)
    n_scenes = len(scenes) if scenes else len(load_schedule(ctx.home, schedule).scenes)
    n_targets = len(targets) if targets else len(TARGET_ORDER)
    n_starts = len(starts) if starts else len(ctx.home.starts)
    return n_scenes * n_targets * n_starts


def expected_bytes(fmt: BagFormat, searches: int, *, compress: bool = True) -> int | None:
    """The size a recording of ``searches`` searches is expected to have (None: not measured)."""
    per = BYTES_PER_SEARCH.get((fmt, compress and fmt is BagFormat.ROS2_MCAP))
    return None if per is None else per * searches


def record(
    out: Path,
    fmt: BagFormat,
    *,
    home: str = "paper",
    scenes: Sequence[int] | None = None,
    targets: Sequence[str] | None = None,
    starts: Sequence[str] | None = None,
    log_dir: Path | None = None,
    topic_map: TopicMap | None = None,
    start_ns: int = DEFAULT_START_NS,
    odom_hz: float = DEFAULT_ODOM_HZ,
    chunk_bytes: int | None = None,
    seed: int = 0,
    compress: bool = True,
    progress: Progress | None = None,
    camera: str = DEFAULT_CAMERA,
) -> Recording:
    """Run the searches and write the bag; the agent's own log goes to ``log_dir`` if given.
    ``camera`` names the simulated search camera that decides what is detected.

    ``progress(stage, done, total)`` hears of each search (stage ``"searches"``) and of the
    messages written (``"messages"``)."""
    from objsearch.agent.session import load_context
    from objsearch.agent.strategies import RunSpec
    from objsearch.sim.longterm import TARGET_ORDER, run_schedule

    topic_map = topic_map or TopicMap()
    _check_out(out, fmt)
    ctx = load_context(home)
    chosen = [ctx.vocabulary.resolve_target(t).name for t in targets] if targets else TARGET_ORDER
    tmp = None if log_dir is not None else Path(tempfile.mkdtemp(prefix="objsearch-record-"))
    log = log_dir if log_dir is not None else tmp
    assert log is not None
    total = planned_searches(home, scenes=scenes, targets=chosen, starts=starts)
    done = 0

    def searched(_: object) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress("searches", done, total)

    try:
        timeline = Timeline()
        trials = run_schedule(
            log,
            RunSpec.of(
                home,
                ctx.home.digest,
                "wpl",
                seed=seed,
                schedule="table2",
                params={"camera": camera},
            ),
            targets=chosen,
            scenes=scenes,
            starts=starts,
            observer=timeline,
            on_trial=searched,
        )
        events = list(read_log(log, store=STORE))
        messages = bag_messages(
            timeline, events, fmt.distro, topic_map, start_ns=start_ns, odom_hz=odom_hz
        )
        n = len(messages)
        counts = write_bag(
            out,
            fmt,
            messages,
            topic_map,
            chunk_bytes=chunk_bytes,
            compress=compress,
            progress=None if progress is None else (lambda k: progress("messages", k, n)),
        )
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    stamps = [t for t, _ in timeline.poses] + [e.time_ns for e in events]
    return Recording(
        path=out,
        format=fmt,
        messages=counts,
        events=len(events),
        tasks=len(trials),
        start_ns=start_ns + min(stamps, default=0),
        end_ns=start_ns + max(stamps, default=0),
    )


def record_mapping_sweep(
    out: Path,
    fmt: BagFormat,
    *,
    home: str = "paper",
    rooms: Sequence[str] | None = None,
    points_per_room: int = 4,
    topic_map: TopicMap | None = None,
    start_ns: int = DEFAULT_START_NS,
    odom_hz: float = DEFAULT_ODOM_HZ,
    chunk_bytes: int | None = None,
    compress: bool = True,
) -> Recording:
    """Write the §4.3 mapping survey as RGB-D: the views ``objsearch map build`` renders, with
    the simulator's masks of every object (the home's movable objects where the data has them)."""
    from objsearch.agent.detect import GroundTruthDetector
    from objsearch.agent.errors import ObjsearchError
    from objsearch.agent.mapping import survey_poses
    from objsearch.agent.session import load_context
    from objsearch.sim.placements import base_placements, table1_removals
    from objsearch.sim.render import SimulatedCamera

    topic_map = topic_map or TopicMap()
    _check_out(out, fmt)
    ctx = load_context(home)
    names = [r.name for r in ctx.home.rooms]
    chosen = list(rooms) if rooms else names
    unknown = sorted(set(chosen) - set(names))
    if unknown:
        raise ObjsearchError(f"unknown room(s) {unknown} in home {home!r}; rooms: {names}")
    if points_per_room < 1:
        raise ObjsearchError(f"points per room must be at least 1, not {points_per_room}")
    poses = survey_poses(ctx.navmap, chosen, points_per_room)
    camera = SimulatedCamera(ctx.home, base_placements(ctx.home, table1_removals(ctx.home)))
    messages = sweep_messages(
        camera,
        poses,
        GroundTruthDetector(),
        fmt.distro,
        topic_map,
        start_ns=start_ns,
        odom_hz=odom_hz,
    )
    counts = write_bag(out, fmt, messages, topic_map, chunk_bytes=chunk_bytes, compress=compress)
    return Recording(
        path=out,
        format=fmt,
        messages=counts,
        events=0,
        tasks=0,
        start_ns=start_ns,
        end_ns=start_ns + max(len(poses) - 1, 0) * SWEEP_VIEW_NS + SWEEP_HOLD_NS,
    )
