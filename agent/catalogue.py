"""The domain's event catalogue: one typed record per event type and version, and the codec.

Each record is a frozen ``msgspec.Struct`` and the one definition of its payload: its types,
literals and bounds are the constraints, its docstring and its fields' :func:`doc` the
descriptions, and ``events/schema/<type>.v<version>.json`` is written from it (``make schemas``,
:mod:`objsearch.agent.schema_files`; never edit those files). Records are built with keywords and
are immutable. :func:`encode` turns one into the payload dict the log stores; :func:`decode` turns
an event (latest version, as ``read_log`` upcasts it) back into its record, validating it on the
way. The upcast steps for old versions live in :mod:`objsearch.agent.upcasters`;
:data:`CATALOGUE` gathers both, with the lake's Eq. 4 tables
(:mod:`objsearch.agent.scene_graph_sql`), and :data:`STORE` is the store built from it: the value
the product hands the log, ``read_log``, snapshots and the lake (:mod:`objsearch.events.store`).

Why msgspec rather than frozen dataclasses: ``msgspec.convert`` checks a payload dict against the
record's types and bounds in C, about as strict as the JSON Schema (no coercion of strings to
numbers, unknown fields refused) and one to two orders of magnitude faster than ``jsonschema``,
which lets the store trust it instead of the schema validator (see ``docs/events.md``).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable, Mapping
from importlib import resources
from types import MappingProxyType
from typing import (
    Annotated,
    Any,
    ClassVar,
    Final,
    Literal,
    Protocol,
    TypeAlias,
    TypeVar,
    overload,
)

import msgspec

from objsearch.agent.scene_graph_sql import DERIVED_TABLES
from objsearch.agent.upcasters import STEPS
from objsearch.events.catalogue import Catalogue
from objsearch.events.envelope import ReadPayload
from objsearch.events.errors import InvalidEventError
from objsearch.events.projection import shared_decodes
from objsearch.events.record_json import RecordCodec
from objsearch.events.store import Store

NonNegative: TypeAlias = Annotated[float, msgspec.Meta(ge=0)]
Probability: TypeAlias = Annotated[float, msgspec.Meta(ge=0, le=1)]
Positive: TypeAlias = Annotated[float, msgspec.Meta(gt=0)]
XY: TypeAlias = tuple[float, float]
XYZ: TypeAlias = tuple[float, float, float]
Box: TypeAlias = tuple[float, float, float, float]
MethodName: TypeAlias = Literal["wpl", "rvp", "sdp", "ecost", "global"]
PlannerName: TypeAlias = Literal["wpl", "rvp", "sdp", "epl"]
UpdateModeName: TypeAlias = Literal["none", "targets", "all"]
RelationModelName: TypeAlias = Literal[
    "eq4",
    "beta",
    "memory",
    "belief",
    "routine-belief",
    "routine-pooled",
    "dist-oracle",
    "slot-oracle",
]
Weekday: TypeAlias = Annotated[int, msgspec.Meta(ge=0, le=6)]
MinuteOfDay: TypeAlias = Annotated[int, msgspec.Meta(ge=0, le=1439)]
ViewReason: TypeAlias = Literal["look", "inside", "on_the_way"]


def doc(description: str) -> msgspec.Meta:
    """A field's description, written into its schema file (``events/schema_writer.py``)."""
    return msgspec.Meta(description=description)


class Record(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A payload of one event type and version (``TYPE``, ``VERSION``)."""

    TYPE: ClassVar[str]
    VERSION: ClassVar[int]


class Part(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A nested object of a payload."""


class PlanarPose(Part, frozen=True):
    """Planar robot pose (REP-103): metres, yaw in radians counter-clockwise from +x; in the map
    frame, except in pose_observed (the frame its frame_id names)."""

    SCHEMA_NAME: ClassVar[str] = "pose"

    x: float
    y: float
    yaw: float


class DayClock(Part, frozen=True):
    """The local time of day a search began: the weekday (0 Monday ... 6 Sunday) and the minute
    after local midnight (what a memory that knows the hour folds, agent/routine_belief.py)."""

    SCHEMA_NAME: ClassVar[str] = "clock"

    weekday: Weekday
    minute: MinuteOfDay

    @classmethod
    def local(cls, when: dt.datetime | None = None) -> DayClock:
        """The local time of day at ``when`` (default: now, the host's clock), as a robot's
        search records it; seconds are dropped."""
        when = when or dt.datetime.now()
        return cls(weekday=when.weekday(), minute=when.hour * 60 + when.minute)


class Support(Part, frozen=True):
    """The nearest static object in the room."""

    SCHEMA_NAME: ClassVar[str] = "support"

    static_id: Annotated[str, doc("Nearest static object instance.")]
    static_class: Annotated[str, doc("Its class.")]
    at: Annotated[
        bool,
        doc("Whether the object is at that static object's viewpoint N_s (Eq. 4)."),
    ]


class Candidate(Part, frozen=True):
    """A static object a plan considered, with its inputs."""

    SCHEMA_NAME: ClassVar[str] = "candidate"

    static_id: Annotated[str, doc("Static object instance id.")]
    static_class: Annotated[str, doc("Its class.")]
    viewpoint: Annotated[
        XY,
        doc("Viewpoint N_s [x, y] from which it is looked at, map frame, metres."),
    ]
    rel: Annotated[Probability, doc("Rel(target, static) used by the plan.")]


class Detection2D(Part, frozen=True):
    """One vision_msgs/Detection2D: its best hypothesis, box and position."""

    SCHEMA_NAME: ClassVar[str] = "detection"

    instance_id: Annotated[str, doc("Detection2D.id (tracking or instance id), possibly empty.")]
    class_id: Annotated[
        str,
        doc("Class of the best-scoring hypothesis (empty if there is none)."),
    ]
    score: Annotated[float, doc("Its score.")]
    bbox: Annotated[Box, doc("[centre x, centre y, width, height], pixels.")]
    position: Annotated[
        XYZ | None,
        doc(
            "The best hypothesis' position [x, y, z] in the header's frame, metres; null "
            "without a hypothesis."
        ),
    ]


class RelationsSpec(Part, frozen=True):
    """A relation model and every parameter it uses."""

    SCHEMA_NAME: ClassVar[str] = "relations"

    model: Annotated[
        RelationModelName,
        doc(
            "eq4: the paper's Eq. 4; beta: a Beta posterior per class pair with negative "
            "evidence; memory: a belief per (target, static instance) from sightings, "
            "misses, recency and frequency, the class-level Beta posterior as prior; "
            "belief: a probability distribution per target over static instances and "
            "elsewhere (agent/belief.py); routine-belief: the belief that knows the hour, "
            "per time-of-day slot and day type mixed with the time-blind belief "
            "(agent/routine_belief.py); routine-pooled: routine-belief with a fourth component, "
            "the mixture of its three whose weights are learned from every class of the "
            "home, and each class's model average added to the home's "
            "(agent/routine_belief.py); dist-oracle: a reference that reads the schedule's "
            "placement distribution (never a default); slot-oracle: the same reference, "
            "knowing the schedule's distribution at each time of day (routine schedules)."
        ),
    ]
    prior_strength: Annotated[
        Positive | None,
        doc(
            "beta, memory: pseudo-observations of the prior; belief, routine-belief, "
            "routine-pooled: the Dirichlet prior's total weight in episodes; null otherwise."
        ),
    ]
    half_life_tasks: Annotated[
        Positive | None,
        doc(
            "beta: half-life of evidence in tasks, null for no decay; memory: half-life of "
            "the recent evidence in tasks; belief, routine-belief, routine-pooled: half-life "
            "of the short memory in episodes (scenes, or tasks where the log records no "
            "scene)."
        ),
    ]
    recent_weight: Annotated[
        NonNegative | None,
        doc(
            "memory: weight of recent (decaying) evidence against long-run counts; null for"
            " other models."
        ),
    ]


class SeedValue(Part, frozen=True):
    """One prior Rel(dynamic, static) value."""

    SCHEMA_NAME: ClassVar[str] = "seed_value"

    dynamic: Annotated[str, doc("Semi-dynamic object class.")]
    static: Annotated[str, doc("Static object class.")]
    rel: Annotated[Probability, doc("Relatedness in [0, 1].")]


class ContainerOpened(Record, frozen=True):
    """The robot opened a container (fridge, microwave, ...)."""

    TYPE: ClassVar[str] = "container_opened"
    VERSION: ClassVar[int] = 1
    static_id: Annotated[str, doc("Container's static object id.")]
    pose: Annotated[PlanarPose, doc("Pose it was opened from.")]


class DetectedV2(Record, frozen=True):
    """Perception reported an object in the last view. v2: the nearest static object is one
    nullable object (v1 had three loose fields)."""

    TYPE: ClassVar[str] = "detection"
    VERSION: ClassVar[int] = 2
    object_class: Annotated[str, doc("Detected class.")]
    instance_id: Annotated[str, doc("Instance id (simulator id, or tracker id on a robot).")]
    mask_area: Annotated[NonNegative, doc("Segmentation mask area, pixels.")]
    position: Annotated[XYZ, doc("Object position [x, y, z], map frame, metres.")]
    accepted: Annotated[bool, doc("Whether the detection passed the mask-area threshold.")]
    support: Annotated[
        Support | None,
        doc("The nearest static object in the room, or null if the room has none."),
    ]


class ClassScore(Part, frozen=True):
    """One class of a detection's class distribution."""

    SCHEMA_NAME: ClassVar[str] = "class_score"

    object_class: Annotated[str, doc("A class the detector weighed.")]
    p: Annotated[Probability, doc("Its probability.")]


class Detected(Record, frozen=True):
    """Perception reported an object in the last view. v3: the detector's score and class
    distribution; ``accepted`` also says whether the agent took it as a sighting (a perfect
    detector's always are)."""

    TYPE: ClassVar[str] = "detection"
    VERSION: ClassVar[int] = 3
    object_class: Annotated[str, doc("Detected class.")]
    instance_id: Annotated[str, doc("Instance id (simulator id, or tracker id on a robot).")]
    mask_area: Annotated[NonNegative, doc("Segmentation mask area, pixels.")]
    position: Annotated[XYZ, doc("Object position [x, y, z], map frame, metres.")]
    accepted: Annotated[
        bool,
        doc(
            "Whether the detection counts as a sighting: it passed the mask-area threshold and "
            "its score (or a confirming look) made it sure enough (docs/perception.md). Only "
            "accepted detections are learned."
        ),
    ]
    support: Annotated[
        Support | None,
        doc("The nearest static object in the room, or null if the room has none."),
    ]
    score: Annotated[
        Probability,
        doc("The detector's confidence; 1 for a perfect detector (v2 and older logs)."),
    ]
    classes: Annotated[
        tuple[ClassScore, ...],
        doc(
            "The detector's class distribution, reported class first; empty when it gave only "
            "object_class at score (v2 and older logs)."
        ),
    ]


class SightingRejected(Record, frozen=True):
    """A sighting of the target that confirmation rejected: not the target, or not sure enough
    after the looks the rule allows (docs/perception.md). It is not learned and does not end the
    search."""

    TYPE: ClassVar[str] = "sighting_rejected"
    VERSION: ClassVar[int] = 1
    object_class: Annotated[str, doc("The class it was reported as (the target's).")]
    instance_id: Annotated[str, doc("Instance id of the first detection.")]
    position: Annotated[XYZ, doc("Its position [x, y, z], map frame, metres.")]
    score: Annotated[Probability, doc("The first detection's score.")]
    posterior: Annotated[Probability, doc("P(the target is there) after the confirming looks.")]
    looks: Annotated[int, msgspec.Meta(ge=0), doc("Confirming looks taken.")]


class Moved(Record, frozen=True):
    """The robot moved (or was teleported between rooms)."""

    TYPE: ClassVar[str] = "moved"
    VERSION: ClassVar[int] = 1
    start: Annotated[PlanarPose, doc("Pose before the move.")]
    end: Annotated[PlanarPose, doc("Pose after the move.")]
    metres: Annotated[NonNegative, doc("Path length driven, metres.")]
    rooms: Annotated[
        tuple[str, ...],
        doc("Rooms traversed, in order (teleports happen between them)."),
    ]
    interrupted: Annotated[
        bool,
        doc("Whether the move stopped early (e.g. the target was seen on the way)."),
    ]


class ObjectsDetected(Record, frozen=True):
    """One camera frame's detections (vision_msgs/Detection2DArray), ingested from a ROS bag."""

    TYPE: ClassVar[str] = "objects_detected"
    VERSION: ClassVar[int] = 1
    frame_id: Annotated[str, doc("Frame of the array's header.")]
    topic: Annotated[str, doc("Bag topic it came from.")]
    detections: Annotated[tuple[Detection2D, ...], doc("The frame's detections, possibly none.")]


class PlanComputed(Record, frozen=True):
    """The planner chose where to look next (a decision, recorded for audit)."""

    TYPE: ClassVar[str] = "plan_computed"
    VERSION: ClassVar[int] = 1
    room: Annotated[str, doc("Room being searched.")]
    room_order: Annotated[tuple[str, ...], doc("Rooms in the order they will be searched.")]
    objective: Annotated[str, doc("Objective the order optimises (e.g. wpl).")]
    alpha: Annotated[float, doc("Alpha used by the objective.")]
    candidates: Annotated[
        tuple[Candidate, ...],
        doc("Static objects considered, with their inputs."),
    ]
    order: Annotated[tuple[str, ...], doc("Chosen visiting order (static ids).")]
    terms: Annotated[
        tuple[float, ...],
        doc("Objective term of each visited stop, in order."),
    ]
    value: Annotated[float, doc("Objective value of the chosen order.")]


class PoseObserved(Record, frozen=True):
    """A robot pose from a recording (odometry, or TF to the base frame), ingested from a ROS
    bag."""

    TYPE: ClassVar[str] = "pose_observed"
    VERSION: ClassVar[int] = 1
    pose: Annotated[PlanarPose, doc("Base frame pose.")]
    frame_id: Annotated[
        str,
        doc("Frame the pose is in: the map frame when map → odom was known, else the odom frame."),
    ]
    topic: Annotated[str, doc("Bag topic it came from.")]


class RunStarted(Record, frozen=True):
    """A run (one experiment or one robot session) began, with its full spec: everything needed
    to fold and re-plan it exactly (relation model and its parameters, planner, room order, α,
    update mode, support radius, schedule)."""

    TYPE: ClassVar[str] = "run_started"
    VERSION: ClassVar[int] = 5
    home: Annotated[str, doc("Home (map) id.")]
    home_digest: Annotated[
        str,
        doc("Digest of the home data, so a replay can tell whether the map changed."),
    ]
    strategy: Annotated[
        str,
        doc("Name of the strategy (objsearch.agent.strategies), e.g. wpl, wpl-neg-decay, epl."),
    ]
    method: Annotated[
        MethodName,
        doc(
            "Room order: wpl and rvp by summed Rel after the start room, sdp random "
            "(seeded), ecost by minimum expected cost over all room orders (an exact DP "
            "over room subsets; the start room is not forced first), global by one plan "
            "over every stop of the home (rooms are not searched whole; planner epl)."
        ),
    ]
    planner: Annotated[
        PlannerName,
        doc(
            "Stop planner inside a room: wpl (Eq. 3), rvp (by Rel), sdp (Eq. 3 with alpha "
            "0), epl (expected path length)."
        ),
    ]
    relations: Annotated[
        RelationsSpec,
        doc("The relation model the log is folded into, with every parameter it uses."),
    ]
    alpha: Annotated[NonNegative, doc("Weight of relatedness in WPL (Eq. 3).")]
    update_mode: Annotated[
        UpdateModeName,
        doc("Which scene-graph relations Eq. 4 updates after each search."),
    ]
    seed: Annotated[int, doc("Seed of every random choice in the run.")]
    support_radius: Annotated[
        NonNegative,
        doc("Metres: an object this close to a static object's box is at it (Eq. 4's experience)."),
    ]
    schedule: Annotated[
        str | None,
        doc(
            "The placement schedule of a simulated run (table2, stats-<seed>, rearr-<seed>,"
            " habit-<seed>), or null."
        ),
    ]
    params: Annotated[
        dict[str, Any],
        doc("Any further parameters, free-form (e.g. the transport of an on-robot run)."),
    ]


class SceneGraphSeeded(Record, frozen=True):
    """The scene graph got its prior relatedness values (Eq. 2)."""

    TYPE: ClassVar[str] = "scene_graph_seeded"
    VERSION: ClassVar[int] = 1
    source: Annotated[str, doc("Where the priors come from (file, dataset, commit).")]
    values: Annotated[tuple[SeedValue, ...], doc("Prior Rel(dynamic, static) values.")]


class RecordQuarantined(Record, frozen=True):
    """Written only by `objsearch log repair`, in the place (seq) of a record it moved out of
    events.log: a record whose bytes were damaged, or one of the records lost or cut from the
    end. It keeps the seq (so no later event takes the lost record's seq or id) and, for a
    record damaged in place, the chain value the next record continues from. Folds ignore it."""

    TYPE: ClassVar[str] = "record_quarantined"
    VERSION: ClassVar[int] = 1
    reason: Annotated[str, doc("What was wrong with the record, as the repair diagnosed it.")]
    quarantine: Annotated[
        str | None,
        doc(
            "The file beside the log that keeps the removed bytes "
            "(events.log.repair-<offset>), or null if the file had already lost them (cut "
            "short before its high-water mark)."
        ),
    ]
    offset: Annotated[int, doc("Where the removed bytes start in the quarantine file.")]
    length: Annotated[
        int,
        doc(
            "How many bytes were removed (for records cut from the end: all of them, shared"
            " by their markers)."
        ),
    ]
    chain: Annotated[
        str | None,
        doc(
            "The checksum (8 lower-case hex digits) the next record's chain starts from: "
            "the damaged record's own stored checksum, which the next record proves. Null: "
            "continue from this record's checksum."
        ),
    ]


class SearchFailed(Record, frozen=True):
    """The search gave up without finding the target."""

    TYPE: ClassVar[str] = "search_failed"
    VERSION: ClassVar[int] = 1
    reason: Annotated[str, doc("Why (e.g. all candidates visited).")]


class TargetFound(Record, frozen=True):
    """The target was found; the search succeeds."""

    TYPE: ClassVar[str] = "target_found"
    VERSION: ClassVar[int] = 1
    instance_id: Annotated[str, doc("Target instance found.")]
    position: Annotated[XYZ, doc("Its position [x, y, z], map frame, metres.")]
    approach: Annotated[PlanarPose, doc("Pose the robot approached it from.")]


class TargetDetected(Record, frozen=True):
    """The target was detected and accepted: the moment the paper's path length (mileage from
    the start to the discovery of the object) is measured. The approach to a viewpoint of the
    target follows; target_found closes it."""

    TYPE: ClassVar[str] = "target_detected"
    VERSION: ClassVar[int] = 1
    instance_id: Annotated[
        str,
        doc("Target instance detected (the first accepted detection of the target in this task)."),
    ]
    position: Annotated[XYZ, doc("Its position as perceived [x, y, z], map frame, metres.")]
    pose: Annotated[PlanarPose, doc("Where the robot stood when it detected it.")]
    path_length: Annotated[
        NonNegative,
        doc(
            "Metres driven since task_started up to this detection (the paper's path length"
            " to discovery); the approach is not included."
        ),
    ]


class TaskAborted(Record, frozen=True):
    """A task that never ended: the agent stopped (crash, kill, power) in the middle of it and
    closed it on restart. It ends the task like task_ended, unsuccessfully, and Eq. 4 folds
    nothing of it."""

    TYPE: ClassVar[str] = "task_aborted"
    VERSION: ClassVar[int] = 1
    target: Annotated[str, doc("The task's target.")]
    reason: Annotated[str, doc("Why it was aborted, e.g. restart.")]
    path_length: Annotated[
        NonNegative,
        doc("Metres walked in the task before it stopped, as its moved events recorded."),
    ]


class TaskEnded(Record, frozen=True):
    """The task is over (after target_found or search_failed)."""

    TYPE: ClassVar[str] = "task_ended"
    VERSION: ClassVar[int] = 1
    target: Annotated[str, doc("Target object class.")]
    success: Annotated[bool, doc("Whether the target was found.")]
    path_length: Annotated[NonNegative, doc("Total path length of the task, metres.")]


class TaskStarted(Record, frozen=True):
    """A search for one target object began."""

    TYPE: ClassVar[str] = "task_started"
    VERSION: ClassVar[int] = 2
    target: Annotated[str, doc("Target object class.")]
    start: Annotated[str, doc("Room the robot starts in.")]
    pose: Annotated[PlanarPose, doc("Start pose.")]
    scene: Annotated[
        int | None,
        doc("Scene (placement schedule) index, or null for a live robot."),
    ]
    clock: Annotated[
        DayClock | None,
        doc(
            "Local time of day the search began (v2): what a memory that knows the hour "
            "folds; null when the caller gave none (v1 logs, runs without a time of day)."
        ),
    ]


class ViewTaken(Record, frozen=True):
    """The robot looked (took an observation)."""

    TYPE: ClassVar[str] = "view_taken"
    VERSION: ClassVar[int] = 2
    pose: Annotated[PlanarPose, doc("Pose the view was taken from.")]
    pitch: Annotated[
        NonNegative,
        doc(
            "Camera tilt, radians down from level (AI2-THOR's horizon); 0 when the robot "
            "has no tilt unit."
        ),
    ]
    static_id: Annotated[str | None, doc("Static object being looked at, or null.")]
    reason: Annotated[ViewReason, doc("Why the view was taken.")]


#: Every record the agent writes, by (type, version): each type's latest, and detection v2,
#: which a perfect detector still writes. Older versions are not classes: they live on as
#: their released schema files (``events/schema/<type>.v<N>.json``, read, never rewritten)
#: and the upcast steps that carry them to the latest (:mod:`objsearch.agent.upcasters`).
RECORDS: Final[Mapping[tuple[str, int], type[Record]]] = {
    (r.TYPE, r.VERSION): r
    for r in (
        ContainerOpened,
        DetectedV2,
        Detected,
        Moved,
        ObjectsDetected,
        PlanComputed,
        PoseObserved,
        RunStarted,
        RecordQuarantined,
        SceneGraphSeeded,
        SearchFailed,
        SightingRejected,
        TargetFound,
        TargetDetected,
        TaskAborted,
        TaskEnded,
        TaskStarted,
        ViewTaken,
    )
}
#: The record of each type's latest version: what :func:`decode` returns for that type.
LATEST: Final[Mapping[str, type[Record]]] = {
    t: RECORDS[t, max(v for tt, v in RECORDS if tt == t)] for t, _ in RECORDS
}

R = TypeVar("R", bound=Record)


class _Typed(Protocol):
    """What :func:`decode` reads: an :class:`~objsearch.events.Event` or any event-like."""

    @property
    def type(self) -> str: ...
    @property
    def payload(self) -> Mapping[str, Any]: ...


def encode(record: Record) -> dict[str, Any]:
    """The payload dict of ``record`` (JSON types only: tuples become lists)."""
    return RecordCodec.payload(record)


@overload
def decode(event: _Typed, as_type: type[R]) -> R: ...
@overload
def decode(event: _Typed, as_type: None = None) -> Record: ...
def decode(event: _Typed, as_type: type[R] | None = None) -> Record:
    """The record of an event at its type's latest version (read through ``read_log``).

    With ``as_type``, the event must be of that record's type: a reader that already matched on
    ``event.type`` gets the precise class back. Raises :class:`InvalidEventError` on a payload
    that does not fit the record (the log validated it, so this means a schema/record mismatch).
    """
    payload = event.payload
    if type(payload) is ReadPayload and as_type is not None:
        # A fold's call on an event read from a log (or appended as a record): the record is
        # decoded from the payload's JSON once, in C, and kept on the payload, so every fold of
        # the event (the agent's state reads a detection in its model and its map evidence)
        # shares that one decode, in a hub or not.
        typed: Any = payload.record
        if type(typed) is as_type:
            return typed
        raw = payload.unread
        if raw is not None and event.type == as_type.TYPE:
            try:
                decoded: R = _JSON_DECODERS[as_type](raw)
            except msgspec.ValidationError:
                pass  # worded by the general path below
            else:
                payload.record = decoded
                return decoded
    shared = shared_decodes(event)
    if shared is None:
        return _decode(event, as_type)
    # A projection hub is handing the event out: every projection and view it tells gets the
    # one record (records are frozen; folds never change what they read).
    key = as_type if as_type is not None else LATEST.get(event.type)
    record: Record | None = shared.get(key)
    if record is None:
        record = _decode(event, as_type)
        shared[key] = record
    return record


def _decode(event: _Typed, as_type: type[R] | None) -> Record:
    payload = event.payload
    if as_type is not None and type(payload) is ReadPayload:
        # A fold's call (read from a log, type matched): the JSON straight into the record, one
        # call; anything else (decoded already, the wrong type, a refusal to word) takes the
        # general path below.
        raw = payload.unread
        if raw is not None and event.type == as_type.TYPE:
            try:
                record: R = _JSON_DECODERS[as_type](raw)
                return record
            except msgspec.ValidationError:
                pass
    record_type = LATEST.get(event.type) if as_type is None else as_type
    if record_type is None or event.type != record_type.TYPE:
        raise InvalidEventError(
            f"no record for event type {event.type!r}"
            + ("" if as_type is None else f" as {as_type.__name__}"),
            event_type=event.type,
            reason="no record",
        )
    return _convert(record_type, event.payload)


def decode_payload(record_type: type[R], payload: Mapping[str, Any]) -> R:
    """``payload`` (of ``record_type``'s type and version) as that record."""
    return _convert(record_type, payload)


def _convert(record_type: type[R], payload: Mapping[str, Any]) -> R:
    try:
        if type(payload) is ReadPayload:
            raw = payload.unread
            if raw is not None:
                # Read from a log and not decoded yet: its JSON straight into the record, in
                # C, the one decode this event gets (the same checks as converting the dict).
                record: R = _JSON_DECODERS[record_type](raw)
                return record
        return msgspec.convert(_as_dict(payload), record_type, strict=True)
    except msgspec.ValidationError as exc:
        where = f"{record_type.TYPE} v{record_type.VERSION}"
        raise InvalidEventError(
            f"invalid {where} event: {exc}",
            event_type=record_type.TYPE,
            version=record_type.VERSION,
            reason=str(exc),
        ) from exc


def accepts(event_type: str, version: int, payload: Mapping[str, Any]) -> bool:
    """Whether ``payload`` fits its record: the store's fast check before ``jsonschema``.

    True means valid (the agreement test holds the records to their schemas); False means "not
    known valid": the store then asks the JSON Schema, which has the last word and the error text.
    """
    record_type = RECORDS.get((event_type, version))
    if record_type is None:
        return False
    try:
        msgspec.convert(_as_dict(payload), record_type, strict=True)
    except msgspec.ValidationError:
        return False
    return True


def _as_dict(payload: Mapping[str, Any]) -> dict[str, Any]:
    """A payload as the dict msgspec converts (which takes no other mapping): itself, or a
    shallow copy — an event's ``MappingProxyType`` copies its dict in C, 7× faster than
    ``dict()`` reading it key by key (measured: 0.19 against 1.38 µs for a detection)."""
    kind = type(payload)
    if kind is dict:
        return payload  # type: ignore[return-value]
    if kind is MappingProxyType:
        return payload.copy()  # type: ignore[attr-defined,no-any-return]
    return dict(payload)


def _catalogue() -> Catalogue:
    return Catalogue(
        schemas=resources.files("objsearch.events").joinpath("schema"),
        upcasters=STEPS,
        accepts=accepts,
        derived=DERIVED_TABLES,
        records=RECORDS,
        schemas_checked=True,  # tests/events/test_schemas.py checks the shipped files
    )


#: The domain's catalogue: the schema files, the upcasters, the records' fast check and the
#: lake's Eq. 4 tables.
CATALOGUE: Final = _catalogue()
#: The product's store, the one value every reader and writer of the agent's events is handed
#: (``EventLog.open(..., store=STORE)``, ``read_log(dir, store=STORE)``, ``Lake(root,
#: store=STORE)``). Building it reads nothing: its schemas compile on first use.
STORE: Final = Store(CATALOGUE)

#: Each record's decoder straight from a payload's JSON text (what ``read_log`` keeps): the
#: store's codecs' own, so each is compiled once for appends and folds alike.
_JSON_DECODERS: Final[Mapping[type[Record], Callable[[Any], Any]]] = {
    record: STORE.record_codec(record).decode for record in RECORDS.values()
}
