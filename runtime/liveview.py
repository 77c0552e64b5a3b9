"""The live view: the agent's events as ROS 2 channels a person can watch in Foxglove.

:class:`LiveView` is a projection (``apply(event)``): it folds the agent's events with the home's
maps and turns each step into messages on the channels below, CDR-encoded with the same ROS 2
types the runtime speaks (rosbags' Humble store plus the repository's ``.msg`` files). Where they go
is the sinks' business (:mod:`objsearch.runtime.livesinks`: a Foxglove WebSocket server, an MCAP
file); every sink gets the same topics, types and bytes.

Everything is derived from the events and the home, so the live agent and a replay of its log
(``objsearch liveview LOG --mcap FILE``) draw the same picture.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Final, Protocol

from objsearch.agent.catalogue import (
    ContainerOpened,
    Detected,
    Moved,
    PlanarPose,
    PlanComputed,
    RunStarted,
    SearchFailed,
    TargetFound,
    TaskEnded,
    TaskStarted,
    ViewTaken,
    decode,
)
from objsearch.agent.geometry import Point, Pose, heading
from objsearch.agent.session import HomeContext
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import AGENT_MODELS, RelationModels
from objsearch.agent.world import Detection
from objsearch.events import Event
from objsearch.events.projection import EventView
from objsearch.runtime import messages as m

log = logging.getLogger("objsearch.liveview")

MAP: Final = "/objsearch/live/map"
STATICS: Final = "/objsearch/live/statics"
PLAN: Final = "/objsearch/live/plan"
ROUTE: Final = "/objsearch/live/route"
ROBOT: Final = "/objsearch/live/robot"
DETECTIONS: Final = "/objsearch/live/detections"
DETECTION_MARKERS: Final = "/objsearch/live/detection_markers"
SCENE_GRAPH: Final = "/objsearch/live/scene_graph"
#: The same scene graph typed (objsearch_msgs/SceneGraph), and the target's belief: typed
#: (objsearch_msgs/Belief) and drawn (each static instance coloured by its probability, labelled).
GRAPH: Final = "/objsearch/live/graph"
BELIEF: Final = "/objsearch/live/belief"
BELIEF_MARKERS: Final = "/objsearch/live/belief_markers"
EVENTS: Final = "/objsearch/live/events"
#: Per-task metrics as numbers a Plot panel draws, one message per ended task (std_msgs/Float64).
PATH_LENGTH: Final = "/objsearch/live/metrics/path_length"
SUCCESS: Final = "/objsearch/live/metrics/success"
TARGET_REL: Final = "/objsearch/live/metrics/target_rel"
FLOAT64: Final = "std_msgs/msg/Float64"
METRICS: Final = (PATH_LENGTH, SUCCESS, TARGET_REL)

SCENE_GRAPH_MSG: Final = "objsearch_msgs/msg/SceneGraph"
BELIEF_MSG: Final = "objsearch_msgs/msg/Belief"
OCCUPANCY_GRID: Final = "nav_msgs/msg/OccupancyGrid"
MARKER_ARRAY: Final = "visualization_msgs/msg/MarkerArray"
PATH: Final = "nav_msgs/msg/Path"

#: A log whose clock is already past this (2001-09-09) is on a wall clock: a robot's, or a bag
#: run's, which ingest put on the agent's header stamps. A simulated log's clock starts at 0.
WALL_CLOCK_NS: Final = 10**18
#: ROS time's seconds are an int32 (builtin_interfaces/Time): the last stamp a message can carry.
MAX_STAMP_NS: Final = (2**31 - 1) * 10**9

#: Every channel with its message type, in the order a viewer lists them.
CHANNELS: Final[Mapping[str, str]] = {
    MAP: OCCUPANCY_GRID,
    STATICS: MARKER_ARRAY,
    PLAN: PATH,
    ROUTE: PATH,
    ROBOT: m.POSE_STAMPED,
    DETECTIONS: m.DETECTIONS,
    DETECTION_MARKERS: MARKER_ARRAY,
    SCENE_GRAPH: m.STRING,
    GRAPH: SCENE_GRAPH_MSG,
    BELIEF: BELIEF_MSG,
    BELIEF_MARKERS: MARKER_ARRAY,
    EVENTS: m.EVENT,
    PATH_LENGTH: FLOAT64,
    SUCCESS: FLOAT64,
    TARGET_REL: FLOAT64,
}

# OccupancyGrid cell values (nav_msgs convention): free, occupied, unknown.
FREE, OCCUPIED, UNKNOWN = 0, 100, -1

# visualization_msgs/Marker type and action constants.
CUBE, SPHERE, LINE_STRIP, TEXT = 1, 2, 4, 9
ADD, DELETEALL = 0, 3


@dataclass(frozen=True, slots=True)
class LiveMessage:
    """One message on one channel: CDR bytes of ``msgtype``, stamped on the agent's clock."""

    topic: str
    msgtype: str
    stamp_ns: int
    data: bytes


class LiveSink(Protocol):
    """Where live messages go. ``write`` is called from the agent's thread only."""

    def write(self, message: LiveMessage) -> None: ...

    def close(self) -> None: ...


# -- message builders --------------------------------------------------------------------------


def _float64(value: float) -> Any:
    return m.types()[FLOAT64](data=float(value))


def _color(r: float, g: float, b: float, a: float = 1.0) -> Any:
    return m.types()["std_msgs/msg/ColorRGBA"](r=r, g=g, b=b, a=a)


def _point(x: float, y: float, z: float = 0.0) -> Any:
    return m.types()["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=float(z))


def _pose(x: float, y: float, z: float = 0.0, yaw: float = 0.0) -> Any:
    t = m.types()
    return t["geometry_msgs/msg/Pose"](
        position=_point(x, y, z),
        orientation=t["geometry_msgs/msg/Quaternion"](
            x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
        ),
    )


def marker(
    stamp_ns: int,
    ns: str,
    id: int,
    type: int,
    *,
    pose: Any = None,
    scale: tuple[float, float, float] = (0.1, 0.1, 0.1),
    color: Any = None,
    points: Sequence[Any] = (),
    text: str = "",
    action: int = ADD,
) -> Any:
    """A ``visualization_msgs/Marker`` with every field the Humble definition requires filled."""
    t = m.types()
    header, texture, mesh_file = _marker_parts(stamp_ns)
    return t["visualization_msgs/msg/Marker"](
        header=header,
        ns=ns,
        id=id,
        type=type,
        action=action,
        pose=pose if pose is not None else _pose(0.0, 0.0),
        scale=t["geometry_msgs/msg/Vector3"](x=scale[0], y=scale[1], z=scale[2]),
        color=color if color is not None else _color(1.0, 1.0, 1.0),
        lifetime=t["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
        frame_locked=False,
        points=list(points),
        colors=[],
        texture_resource="",
        texture=texture,
        uv_coordinates=[],
        text=text,
        mesh_resource="",
        mesh_file=mesh_file,
        mesh_use_embedded_materials=False,
    )


@lru_cache(maxsize=4)
def _marker_parts(stamp_ns: int) -> tuple[Any, Any, Any]:
    """The header and the empty texture and mesh of a stamp's markers, built once and shared by
    all of them (messages are never mutated; building them is most of the cost of a view)."""
    import numpy as np

    t = m.types()
    texture = t["sensor_msgs/msg/CompressedImage"](
        header=m.header(stamp_ns), format="", data=np.zeros(0, dtype=np.uint8)
    )
    mesh = t["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, dtype=np.uint8))
    return m.header(stamp_ns), texture, mesh


def marker_array(markers: Sequence[Any]) -> Any:
    return m.types()[MARKER_ARRAY](markers=list(markers))


def probability_color(p: float) -> Any:
    """Grey (nothing) through orange to red (certain), on a square-root scale so that the small
    probabilities of a spread belief still differ; opaque enough to read over the statics."""
    v = math.sqrt(min(max(p, 0.0), 1.0))
    return _color(0.6 + 0.4 * v, 0.6 * (1.0 - v), 0.6 * (1.0 - v), 0.35 + 0.6 * v)


def belief_markers(
    ctx: HomeContext, stamp_ns: int, target: str, probability: Mapping[str, float]
) -> Any:
    """Every static instance as a box coloured by the target's probability there
    (:func:`probability_color`), with a label ``Class p %``; statics without mass are grey."""
    out = [marker(stamp_ns, "belief", 0, CUBE, action=DELETEALL)]
    for i, (static_id, static) in enumerate(sorted(ctx.home.statics.items())):
        p = probability.get(static_id, 0.0)
        (x, y, z), (sx, sy, sz) = static.box.center, static.box.size
        out.append(
            marker(
                stamp_ns,
                "belief",
                2 * i + 1,
                CUBE,
                pose=_pose(x, y, z),
                scale=(max(sx, 0.05), max(sy, 0.05), max(sz, 0.05)),
                color=probability_color(p),
            )
        )
        out.append(
            marker(
                stamp_ns,
                "belief",
                2 * i + 2,
                TEXT,
                pose=_pose(x, y, z + sz / 2 + 0.15),
                scale=(0.1, 0.1, 0.1),
                color=_color(1.0, 1.0, 1.0),
                text=f"{static.cls} {100 * p:.1f} %" if p > 0 else f"{static.cls} ({target}: 0)",
            )
        )
    return marker_array(out)


def occupancy_grid(ctx: HomeContext, stamp_ns: int) -> Any:
    """Viewpoints free, each room's viewpoint box grown by one cell occupied (walls and furniture
    the robot cannot stand on), the rest unknown; one cell per viewpoint, centred on it."""
    import numpy as np

    t = m.types()
    g = ctx.home.grid
    points = list(ctx.navmap.room_of)
    x0 = min(p.x for p in points) - 2 * g
    y0 = min(p.y for p in points) - 2 * g
    width = round((max(p.x for p in points) + 2 * g - x0) / g) + 1
    height = round((max(p.y for p in points) + 2 * g - y0) / g) + 1
    cells = np.full((height, width), UNKNOWN, dtype=np.int8)

    def index(p: Point) -> tuple[int, int]:
        return round((p.y - y0) / g), round((p.x - x0) / g)

    for room in ctx.home.rooms:
        (r0, c0), (r1, c1) = (
            index(Point(min(p.x for p in room.viewpoints), min(p.y for p in room.viewpoints))),
            index(Point(max(p.x for p in room.viewpoints), max(p.y for p in room.viewpoints))),
        )
        cells[r0 - 1 : r1 + 2, c0 - 1 : c1 + 2] = OCCUPIED
    for p in points:
        cells[index(p)] = FREE
    return t[OCCUPANCY_GRID](
        header=m.header(stamp_ns),
        info=t["nav_msgs/msg/MapMetaData"](
            map_load_time=m.stamp(stamp_ns),
            resolution=float(g),
            width=width,
            height=height,
            # The origin is the outer corner of cell (0, 0), so cell centres land on viewpoints.
            origin=_pose(x0 - g / 2, y0 - g / 2),
        ),
        data=cells.ravel(),
    )


def statics_markers(ctx: HomeContext, stamp_ns: int) -> Any:
    """A translucent box and a label per static object (containers blue), a label per room."""
    out = []
    for i, room in enumerate(ctx.home.rooms):
        out.append(
            marker(
                stamp_ns,
                "rooms",
                i,
                TEXT,
                pose=_pose(room.door.x, room.door.y, 2.2),
                scale=(0.4, 0.4, 0.4),
                text=room.name,
            )
        )
    for i, s in enumerate(sorted(ctx.home.statics.values(), key=lambda s: s.id)):
        (cx, cy, cz), (sx, sy, sz) = s.box.center, s.box.size
        color = _color(0.2, 0.4, 0.9, 0.45) if s.container else _color(0.6, 0.6, 0.6, 0.45)
        out.append(
            marker(
                stamp_ns,
                "statics",
                i,
                CUBE,
                pose=_pose(cx, cy, cz),
                scale=(max(sx, 0.02), max(sy, 0.02), max(sz, 0.02)),
                color=color,
            )
        )
        out.append(
            marker(
                stamp_ns,
                "static_labels",
                i,
                TEXT,
                pose=_pose(cx, cy, cz + sz / 2 + 0.15),
                scale=(0.15, 0.15, 0.15),
                text=s.cls,
            )
        )
    return marker_array(out)


def path(points: Sequence[Point | Pose], stamp_ns: int) -> Any:
    """A ``nav_msgs/Path`` through ``points``; a point without a yaw faces the next one."""
    poses = [path_pose(points, i, stamp_ns) for i in range(len(points))]
    return m.types()[PATH](header=m.header(stamp_ns), poses=poses)


def path_pose(points: Sequence[Point | Pose], i: int, stamp_ns: int) -> Any:
    """Pose ``i`` of :func:`path`; it depends on point ``i + 1`` (unless ``i`` is a Pose)."""
    p = points[i]
    if isinstance(p, Pose):
        yaw = p.yaw
    elif i + 1 < len(points):
        yaw = heading(p, points[i + 1])
    else:
        yaw = heading(points[i - 1], p) if i else 0.0
    return m.pose_stamped(Pose(p[0], p[1], yaw), stamp_ns)


def _pose_of(pose: PlanarPose) -> Pose:
    return Pose(pose.x, pose.y, pose.yaw)


# -- the projection ----------------------------------------------------------------------------


@dataclass
class _LiveTask:
    task_id: str
    target: str
    route: list[Point] = field(default_factory=list)
    plan: dict[str, Any] | None = None
    detections: list[Detected] = field(default_factory=list)
    # Built messages, kept so that each new message (the whole route, every detection of the
    # task: a late viewer needs only the last one) costs the new parts, not all of them again.
    route_poses: list[Any] = field(default_factory=list)
    detection_markers: list[tuple[Any, ...]] = field(default_factory=list)
    found: str | None = None
    status: str = "searching"
    #: Rel(target, ·) as the task began (before this task's Eq. 4 update).
    rel_before: dict[str, float] = field(default_factory=dict)


class LiveView:
    """Folds events into the live channels and writes them to ``sinks``.

    ``clock_offset_ns`` is added to every event's ``time_ns`` to stamp its messages: 0 on a robot
    (its clock is already absolute), ``record.DEFAULT_START_NS`` for a simulated log, so a replayed
    view lines up with ``objsearch record``'s bag of the same run.
    """

    def __init__(
        self,
        ctx: HomeContext,
        sinks: Sequence[LiveSink],
        *,
        clock_offset_ns: int = 0,
        models: RelationModels = AGENT_MODELS,
        agent: AgentState | None = None,
        memory: Callable[[], AgentState | None] | None = None,
    ) -> None:
        """``agent``: the running agent's own state, kept by its session's projection hub, which
        folds each event into it before the view draws the event; the view then reads it and
        never folds it (None: the view folds a state of its own, with ``models``). ``memory``:
        the agent's ``where`` memory likewise (``agent/where.py``, the belief whatever the run's
        model), drawn as the belief channels; None: the view folds one of its own."""
        self.ctx = ctx
        self.sinks = tuple(sinks)
        self.clock_offset_ns = clock_offset_ns
        #: What the agent knew: the same fold (run spec, relation model, tasks) as everywhere.
        self.agent = agent if agent is not None else AgentState(models=models)
        self._folds = agent is None
        self._memory_fold: AgentState | None = None
        if memory is None:
            from objsearch.agent.where import memory_state

            fresh = memory_state(())
            self._memory_fold = fresh
            memory = lambda: fresh  # noqa: E731
        self._memory = memory
        self.pose: Pose | None = None
        self.task: _LiveTask | None = None
        self.written: dict[str, int] = {}
        self._map_sent = False

    def fold(self, events: Iterable[Event]) -> None:
        """Catch up with events already in the log without drawing them."""
        if not self._folds:
            raise ValueError("this view reads the agent's state, which its hub folds")
        for event in events:
            self.agent.apply(event)
            if self._memory_fold is not None:
                self._memory_fold.apply(event)

    def apply(self, event: EventView) -> None:
        """Draw one event (a projection: ``Session(observers=[view])``)."""
        assert isinstance(event, Event)  # the log's events; EventView is the fold's protocol
        if self._folds:
            self.agent.apply(event)
        if self._memory_fold is not None:
            self._memory_fold.apply(event)
        stamp = self.clock_offset_ns + event.time_ns
        if not 0 <= stamp <= MAX_STAMP_NS:
            from objsearch.agent.errors import ObjsearchError

            raise ObjsearchError(
                f"event {event.seq} ({event.type}): its time {event.time_ns} ns"
                + (f" + the clock offset {self.clock_offset_ns} ns" if self.clock_offset_ns else "")
                + " is outside ROS time (0 to 2038-01-19, int32 seconds)"
            )
        if not self._map_sent:
            self._map_sent = True
            self._send(MAP, stamp, occupancy_grid(self.ctx, stamp))
            self._send(STATICS, stamp, statics_markers(self.ctx, stamp))
        self._send(EVENTS, stamp, m.event(event, stamp))
        handler = getattr(self, f"_on_{event.type}", None)
        if handler is not None:
            handler(event, stamp)

    # -- event handlers (named after the event types) -----------------------------------------

    def _on_scene_graph_seeded(self, event: Event, stamp: int) -> None:
        self._send_graph(event, stamp)

    def _on_task_started(self, event: Event, stamp: int) -> None:
        started = decode(event, TaskStarted)
        self.pose = _pose_of(started.pose)
        self.task = _LiveTask(event.task_id or "", started.target, route=[self._on_grid(self.pose)])
        model = self.agent.model
        self.task.rel_before = model.as_table().get(started.target, {}) if model else {}
        self.task.route_poses = [path_pose(self.task.route, 0, stamp)]
        self._send(ROBOT, stamp, m.pose_stamped(self.pose, stamp))
        self._send(ROUTE, stamp, path(self.task.route, stamp))
        self._send(PLAN, stamp, path([], stamp))
        self._send(DETECTION_MARKERS, stamp, self._detection_markers(stamp))
        self._send_graph(event, stamp)
        self._send_belief(stamp)

    def _on_plan_computed(self, event: Event, stamp: int) -> None:
        plan = decode(event, PlanComputed)
        viewpoint = {c.static_id: Point(*c.viewpoint) for c in plan.candidates}
        stops: list[Point] = []
        for static_id in plan.order:
            vp = viewpoint[static_id]
            if not stops or stops[-1] != vp:  # statics sharing a viewpoint are one stop
                stops.append(vp)
        if self.task is not None:
            self.task.plan = {
                "room": plan.room,
                "room_order": list(plan.room_order),
                "objective": plan.objective,
                "order": list(plan.order),
                "value": plan.value,
                "candidates": [
                    {"static_id": c.static_id, "static_class": c.static_class, "rel": c.rel}
                    for c in plan.candidates
                ],
            }
        self._send(PLAN, stamp, path(stops, stamp))
        self._send_graph(event, stamp)
        self._send_belief(stamp)

    def _on_moved(self, event: Event, stamp: int) -> None:
        moved = decode(event, Moved)
        start, end = _pose_of(moved.start), _pose_of(moved.end)
        self.pose = end
        if self.task is not None:
            a, b = self._on_grid(start), self._on_grid(end)
            try:
                walked = self.ctx.navmap.path(a, b)
            except ValueError:  # not on one graph (a home that changed under the log): a jump
                walked = [a, b]
            if self.task.route and self.task.route[-1] == walked[0]:
                walked = walked[1:]
            route = self.task.route
            route.extend(walked)
            # The last pose faced back along the route; it now faces the next point.
            poses = self.task.route_poses[: max(len(self.task.route_poses) - 1, 0)]
            poses.extend(path_pose(route, i, stamp) for i in range(len(poses), len(route)))
            self.task.route_poses = poses
            self._send(ROUTE, stamp, m.types()[PATH](header=m.header(stamp), poses=poses))
        self._send(ROBOT, stamp, m.pose_stamped(end, stamp))

    def _on_view_taken(self, event: Event, stamp: int) -> None:
        looked = decode(event)
        assert isinstance(looked, ViewTaken | ContainerOpened)
        self.pose = _pose_of(looked.pose)
        self._send(ROBOT, stamp, m.pose_stamped(self.pose, stamp))

    def _on_container_opened(self, event: Event, stamp: int) -> None:
        self._on_view_taken(event, stamp)

    def _on_detection(self, event: Event, stamp: int) -> None:
        detected = decode(event, Detected)
        det = Detection(
            detected.object_class, detected.instance_id, detected.mask_area, detected.position
        )
        self._send(DETECTIONS, stamp, m.detections(stamp, self.pose or Pose(0, 0, 0), [det]))
        if self.task is not None:
            self.task.detections.append(detected)
            self._send(DETECTION_MARKERS, stamp, self._detection_markers(stamp))

    def _on_target_found(self, event: Event, stamp: int) -> None:
        if self.task is not None:
            self.task.found = decode(event, TargetFound).instance_id
            self.task.status = "found"
            self.task.detection_markers.clear()  # the found one changes colour: redraw
            self._send(DETECTION_MARKERS, stamp, self._detection_markers(stamp))
        self._send_graph(event, stamp)

    def _on_search_failed(self, event: Event, stamp: int) -> None:
        if self.task is not None:
            self.task.status = f"failed: {decode(event, SearchFailed).reason}"
        self._send_graph(event, stamp)

    def _on_task_ended(self, event: Event, stamp: int) -> None:
        # The graph has folded the task's experience (Eq. 4) by now: show the updated values.
        if self.task is not None and self.task.status == "searching":
            self.task.status = "ended"
        ended = decode(event, TaskEnded)
        self._send_graph(event, stamp, path_length=ended.path_length)
        self._send_belief(stamp)
        self._send(PATH_LENGTH, stamp, _float64(ended.path_length))
        self._send(SUCCESS, stamp, _float64(1.0 if ended.success else 0.0))
        found_at = self._found_static()
        if self.task is not None and found_at is not None:
            self._send(TARGET_REL, stamp, _float64(self.task.rel_before.get(found_at, 0.0)))

    def _found_static(self) -> str | None:
        """The static class the found target stood at (its accepted detection's support)."""
        task = self.task
        if task is None or task.found is None:
            return None
        for d in task.detections:
            if d.instance_id == task.found and d.support is not None and d.support.at:
                return d.support.static_class
        return None

    # -- helpers ------------------------------------------------------------------------------

    def _on_grid(self, pose: Pose) -> Point:
        """The viewpoint the robot stands on (the runtime accepts poses within 5 cm of one)."""
        nav = self.ctx.navmap
        return nav.nearest_viewpoint(pose.x, pose.y, nav.room_at(pose.x, pose.y))

    def _detection_markers(self, stamp: int) -> Any:
        out = [marker(stamp, "detections", 0, SPHERE, action=DELETEALL)]
        task = self.task
        if task is None:
            return marker_array(out)
        built = task.detection_markers
        for i in range(len(built), len(task.detections)):
            d = task.detections[i]
            x, y, z = d.position
            if d.instance_id == task.found:
                color, label = _color(0.1, 0.9, 0.1), f"{d.object_class} (found)"
            elif d.object_class == task.target:
                color, label = _color(1.0, 0.6, 0.0), f"{d.object_class} (target, not accepted)"
            elif d.accepted:
                color, label = _color(0.9, 0.9, 0.2), d.object_class
            else:
                color, label = _color(0.5, 0.5, 0.5), f"{d.object_class} (below threshold)"
            sphere = marker(
                stamp, "detections", 2 * i + 1, SPHERE, pose=_pose(x, y, z), color=color
            )
            text = marker(
                stamp,
                "detections",
                2 * i + 2,
                TEXT,
                pose=_pose(x, y, z + 0.2),
                scale=(0.12, 0.12, 0.12),
                text=label,
            )
            built.append((sphere, text))
        for pair in built:
            out.extend(pair)
        return marker_array(out)

    def _send_graph(self, event: Event, stamp: int, **extra: Any) -> None:
        task = self.task
        model = self.agent.model
        table = model.as_table() if model is not None else {}
        doc: dict[str, Any] = {
            "seq": event.seq,
            "event": event.type,
            "tasks_folded": self.agent.tasks.ended + self.agent.tasks.aborted,
            "task": None,
            "relations": table,
        }
        if task is not None:
            row = table.get(task.target, {})
            doc["task"] = {
                "task_id": task.task_id,
                "target": task.target,
                "status": task.status,
                "found": task.found,
                # Rel(target, s) for every static class, most likely first: what the plan ranks.
                "rel": dict(sorted(row.items(), key=lambda kv: (-kv[1], kv[0]))),
                "plan": task.plan,
                **extra,
            }
        self._send(SCENE_GRAPH, stamp, m.string(json.dumps(doc, sort_keys=False)))
        self._send(GRAPH, stamp, self._graph_msg(doc, stamp))

    def _graph_msg(self, doc: Mapping[str, Any], stamp: int) -> Any:
        """The scene-graph document as ``objsearch_msgs/SceneGraph`` (every Rel > 0)."""
        t = m.types()
        relation = t["objsearch_msgs/msg/Relation"]
        task = doc["task"] or {}
        plan = task.get("plan") or {}
        return t[SCENE_GRAPH_MSG](
            header=m.header(stamp),
            seq=int(doc["seq"]),
            event=str(doc["event"]),
            tasks_folded=int(doc["tasks_folded"]),
            relations=[
                relation(dynamic_class=d, static_class=s, rel=float(v))
                for d, row in sorted(doc["relations"].items())
                for s, v in sorted(row.items())
                if v > 0
            ],
            task_id=str(task.get("task_id") or ""),
            target=str(task.get("target") or ""),
            status=str(task.get("status") or ""),
            room=str(plan.get("room") or ""),
            room_order=[str(r) for r in plan.get("room_order", [])],
            order=[str(o) for o in plan.get("order", [])],
            path_length=float(task.get("path_length") or 0.0),
        )

    def _send_belief(self, stamp: int) -> None:
        """Where the agent's memory puts the task's target now (``agent/where.py``'s answer over
        every mapped place, as ``objsearch where`` gives it), typed and drawn."""
        from objsearch.agent.errors import ObjsearchError
        from objsearch.agent.where import answer
        from objsearch.runtime.agent_interfaces import places, rooms, sighting

        task, memory = self.task, self._memory()
        if task is None or memory is None or memory.run is None:
            return
        try:
            got = answer(memory, task.target, self.ctx.home, top=len(self.ctx.home.statics))
        except ObjsearchError:
            return  # a class the memory does not know
        likely = list(got["most_likely_now"])
        self._send(
            BELIEF,
            stamp,
            m.types()[BELIEF_MSG](
                header=m.header(stamp),
                target=task.target,
                task_id=task.task_id,
                tasks=int(got.get("tasks") or 0),
                places=places(self.ctx.home, likely),
                rooms=rooms(list(got.get("rooms") or [])),
                elsewhere=float(got.get("elsewhere") or 0.0),
                last_seen=sighting(got.get("last_seen")),
            ),
        )
        probability = {str(p["static_id"]): float(p["probability"]) for p in likely}
        self._send(BELIEF_MARKERS, stamp, belief_markers(self.ctx, stamp, task.target, probability))

    def _send(self, topic: str, stamp: int, msg: Any) -> None:
        msgtype = CHANNELS[topic]
        message = LiveMessage(topic, msgtype, stamp, m.encode(msg, msgtype))
        for sink in self.sinks:
            sink.write(message)
        self.written[topic] = self.written.get(topic, 0) + 1


def render(
    events: Iterable[Event], sinks: Sequence[LiveSink], *, clock_offset_ns: int = 0
) -> LiveView:
    """Draw a recorded log on ``sinks`` (the caller closes them); the home is the one its
    ``run_started`` names. ``clock_offset_ns`` is added only to a simulated clock: a log whose
    ``run_started`` is already on a wall clock (:data:`WALL_CLOCK_NS`) is drawn as it is."""
    from objsearch.agent.errors import ObjsearchError
    from objsearch.agent.session import load_context

    view: LiveView | None = None
    for event in events:
        if event.type == "run_started":
            spec = decode(event, RunStarted)
            home = spec.home
            if view is not None and view.ctx.home.name != home:
                raise ObjsearchError(
                    f"event {event.seq}: the log changes home from {view.ctx.home.name!r} "
                    f"to {home!r}; one live view draws one home"
                )
            if view is None:
                ctx = load_context(home)
                if ctx.home.digest != spec.home_digest:
                    log.warning(
                        "home %r has changed since the log was written (digest %s, now %s): "
                        "the map drawn is today's",
                        home,
                        spec.home_digest,
                        ctx.home.digest,
                    )
                simulated = event.time_ns < WALL_CLOCK_NS
                view = LiveView(ctx, sinks, clock_offset_ns=clock_offset_ns if simulated else 0)
        if view is None:
            raise ObjsearchError(
                f"event {event.seq} ({event.type}) comes before any run_started: "
                "the live view needs to know the home"
            )
        view.apply(event)
    if view is None:
        raise ObjsearchError("the log holds no events")
    return view
