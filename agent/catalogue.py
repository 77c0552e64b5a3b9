"""The domain's event catalogue: one typed record per event type and version, and the codec.

Each record is a frozen ``msgspec.Struct`` whose fields are exactly its JSON Schema's
(``events/schema/<type>.v<version>.json``; ``tests/agent/test_catalogue.py`` checks every field,
type, nullability, enum and bound against the schema files). Records are built with keywords and
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
from objsearch.events.store import Store

NonNegative: TypeAlias = Annotated[float, msgspec.Meta(ge=0)]
Probability: TypeAlias = Annotated[float, msgspec.Meta(ge=0, le=1)]
Positive: TypeAlias = Annotated[float, msgspec.Meta(gt=0)]
XY: TypeAlias = tuple[float, float]
XYZ: TypeAlias = tuple[float, float, float]
Box: TypeAlias = tuple[float, float, float, float]
#: v3's methods; v4 added ``global`` (the whole-home planner).
MethodNameV3: TypeAlias = Literal["wpl", "rvp", "sdp", "ecost"]
MethodName: TypeAlias = Literal["wpl", "rvp", "sdp", "ecost", "global"]
PlannerName: TypeAlias = Literal["wpl", "rvp", "sdp", "epl"]
UpdateModeName: TypeAlias = Literal["none", "targets", "all"]
RelationModelName: TypeAlias = Literal[
    "eq4", "beta", "memory", "belief", "routine-belief", "dist-oracle", "slot-oracle"
]
RelationModelNameV3: TypeAlias = Literal["eq4", "beta", "memory", "belief", "dist-oracle"]
Weekday: TypeAlias = Annotated[int, msgspec.Meta(ge=0, le=6)]
MinuteOfDay: TypeAlias = Annotated[int, msgspec.Meta(ge=0, le=1439)]
ViewReason: TypeAlias = Literal["look", "inside", "on_the_way"]


class Record(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A payload of one event type and version (``TYPE``, ``VERSION``)."""

    TYPE: ClassVar[str]
    VERSION: ClassVar[int]


class Part(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A nested object of a payload."""


class PlanarPose(Part, frozen=True):
    """Planar robot pose in the map frame (REP-103): metres, yaw in radians from +x."""

    x: float
    y: float
    yaw: float


class DayClock(Part, frozen=True):
    """The local time of day a search began: the weekday (0 Monday … 6 Sunday) and the minute
    after midnight (what a memory that knows the hour folds, agent/routine_belief.py)."""

    weekday: Weekday
    minute: MinuteOfDay

    @classmethod
    def local(cls, when: dt.datetime | None = None) -> DayClock:
        """The local time of day at ``when`` (default: now, the host's clock), as a robot's
        search records it; seconds are dropped."""
        when = when or dt.datetime.now()
        return cls(weekday=when.weekday(), minute=when.hour * 60 + when.minute)


class Support(Part, frozen=True):
    static_id: str
    static_class: str
    at: bool


class Candidate(Part, frozen=True):
    static_id: str
    static_class: str
    viewpoint: XY
    rel: Probability


class Detection2D(Part, frozen=True):
    instance_id: str
    class_id: str
    score: float
    bbox: Box
    position: XYZ | None


class RelationsSpecV2(Part, frozen=True):
    model: Literal["eq4", "beta"]
    prior_strength: Positive | None
    half_life_tasks: Positive | None


class RelationsSpecV3(Part, frozen=True):
    model: RelationModelNameV3
    prior_strength: Positive | None
    half_life_tasks: Positive | None
    recent_weight: NonNegative | None


class RelationsSpec(Part, frozen=True):
    model: RelationModelName
    prior_strength: Positive | None
    half_life_tasks: Positive | None
    recent_weight: NonNegative | None


class SeedValue(Part, frozen=True):
    dynamic: str
    static: str
    rel: Probability


class ContainerOpened(Record, frozen=True):
    TYPE: ClassVar[str] = "container_opened"
    VERSION: ClassVar[int] = 1
    static_id: str
    pose: PlanarPose


class DetectionV1(Record, frozen=True):
    TYPE: ClassVar[str] = "detection"
    VERSION: ClassVar[int] = 1
    object_class: str
    instance_id: str
    mask_area: NonNegative
    position: XYZ
    accepted: bool
    nearest_static_id: str | None
    nearest_static_class: str | None
    at_static: bool


class Detected(Record, frozen=True):
    TYPE: ClassVar[str] = "detection"
    VERSION: ClassVar[int] = 2
    object_class: str
    instance_id: str
    mask_area: NonNegative
    position: XYZ
    accepted: bool
    support: Support | None


class Moved(Record, frozen=True):
    TYPE: ClassVar[str] = "moved"
    VERSION: ClassVar[int] = 1
    start: PlanarPose
    end: PlanarPose
    metres: NonNegative
    rooms: tuple[str, ...]
    interrupted: bool


class ObjectsDetected(Record, frozen=True):
    TYPE: ClassVar[str] = "objects_detected"
    VERSION: ClassVar[int] = 1
    frame_id: str
    topic: str
    detections: tuple[Detection2D, ...]


class PlanComputed(Record, frozen=True):
    TYPE: ClassVar[str] = "plan_computed"
    VERSION: ClassVar[int] = 1
    room: str
    room_order: tuple[str, ...]
    objective: str
    alpha: float
    candidates: tuple[Candidate, ...]
    order: tuple[str, ...]
    terms: tuple[float, ...]
    value: float


class PoseObserved(Record, frozen=True):
    TYPE: ClassVar[str] = "pose_observed"
    VERSION: ClassVar[int] = 1
    pose: PlanarPose
    frame_id: str
    topic: str


class RunStartedV1(Record, frozen=True):
    TYPE: ClassVar[str] = "run_started"
    VERSION: ClassVar[int] = 1
    home: str
    home_digest: str
    method: Literal["wpl", "rvp", "sdp", "epl"]
    alpha: NonNegative
    update_mode: Literal["none", "targets", "all"]
    seed: int
    params: dict[str, Any]


class RunStartedV2(Record, frozen=True):
    TYPE: ClassVar[str] = "run_started"
    VERSION: ClassVar[int] = 2
    home: str
    home_digest: str
    strategy: str
    method: Literal["wpl", "rvp", "sdp"]
    planner: Literal["wpl", "rvp", "sdp", "epl"]
    relations: RelationsSpecV2
    alpha: NonNegative
    update_mode: Literal["none", "targets", "all"]
    seed: int
    support_radius: NonNegative
    schedule: str | None
    params: dict[str, Any]


class RunStartedV3(Record, frozen=True):
    TYPE: ClassVar[str] = "run_started"
    VERSION: ClassVar[int] = 3
    home: str
    home_digest: str
    strategy: str
    method: MethodNameV3
    planner: PlannerName
    relations: RelationsSpecV3
    alpha: NonNegative
    update_mode: UpdateModeName
    seed: int
    support_radius: NonNegative
    schedule: str | None
    params: dict[str, Any]


class RunStarted(Record, frozen=True):
    TYPE: ClassVar[str] = "run_started"
    VERSION: ClassVar[int] = 4
    home: str
    home_digest: str
    strategy: str
    method: MethodName
    planner: PlannerName
    relations: RelationsSpec
    alpha: NonNegative
    update_mode: UpdateModeName
    seed: int
    support_radius: NonNegative
    schedule: str | None
    params: dict[str, Any]


class SceneGraphSeeded(Record, frozen=True):
    TYPE: ClassVar[str] = "scene_graph_seeded"
    VERSION: ClassVar[int] = 1
    source: str
    values: tuple[SeedValue, ...]


class RecordQuarantined(Record, frozen=True):
    """Written by ``objsearch log repair`` in the place of a record it moved out (docs/events.md)."""

    TYPE: ClassVar[str] = "record_quarantined"
    VERSION: ClassVar[int] = 1
    reason: str
    quarantine: str | None
    offset: int
    length: int
    chain: str | None


class SearchFailed(Record, frozen=True):
    TYPE: ClassVar[str] = "search_failed"
    VERSION: ClassVar[int] = 1
    reason: str


class TargetFound(Record, frozen=True):
    TYPE: ClassVar[str] = "target_found"
    VERSION: ClassVar[int] = 1
    instance_id: str
    position: XYZ
    approach: PlanarPose


class TargetDetected(Record, frozen=True):
    TYPE: ClassVar[str] = "target_detected"
    VERSION: ClassVar[int] = 1
    instance_id: str
    position: XYZ
    pose: PlanarPose
    path_length: NonNegative


class TaskAborted(Record, frozen=True):
    TYPE: ClassVar[str] = "task_aborted"
    VERSION: ClassVar[int] = 1
    target: str
    reason: str
    path_length: NonNegative


class TaskEnded(Record, frozen=True):
    TYPE: ClassVar[str] = "task_ended"
    VERSION: ClassVar[int] = 1
    target: str
    success: bool
    path_length: NonNegative


class TaskStartedV1(Record, frozen=True):
    TYPE: ClassVar[str] = "task_started"
    VERSION: ClassVar[int] = 1
    target: str
    start: str
    pose: PlanarPose
    scene: int | None


class TaskStarted(Record, frozen=True):
    TYPE: ClassVar[str] = "task_started"
    VERSION: ClassVar[int] = 2
    target: str
    start: str
    pose: PlanarPose
    scene: int | None
    clock: DayClock | None  # v2


class ViewTakenV1(Record, frozen=True):
    TYPE: ClassVar[str] = "view_taken"
    VERSION: ClassVar[int] = 1
    pose: PlanarPose
    static_id: str | None
    reason: ViewReason


class ViewTaken(Record, frozen=True):
    TYPE: ClassVar[str] = "view_taken"
    VERSION: ClassVar[int] = 2
    pose: PlanarPose
    pitch: NonNegative  # camera tilt, radians down (v2)
    static_id: str | None
    reason: ViewReason


#: Every record, old versions included, by (type, version).
RECORDS: Final[Mapping[tuple[str, int], type[Record]]] = {
    (r.TYPE, r.VERSION): r
    for r in (
        ContainerOpened,
        DetectionV1,
        Detected,
        Moved,
        ObjectsDetected,
        PlanComputed,
        PoseObserved,
        RunStartedV1,
        RunStartedV2,
        RunStartedV3,
        RunStarted,
        RecordQuarantined,
        SceneGraphSeeded,
        SearchFailed,
        TargetFound,
        TargetDetected,
        TaskAborted,
        TaskEnded,
        TaskStartedV1,
        TaskStarted,
        ViewTakenV1,
        ViewTaken,
    )
}
#: The record of each type's latest version: what :func:`decode` returns for that type.
LATEST: Final[Mapping[str, type[Record]]] = {
    t: RECORDS[t, max(v for tt, v in RECORDS if tt == t)] for t, _ in RECORDS
}

R = TypeVar("R", bound=Record)
#: Each record's decoder straight from a payload's JSON text (what ``read_log`` keeps).
_JSON_DECODERS: Final[Mapping[type[Record], Callable[[Any], Any]]] = {
    record: msgspec.json.Decoder(record, strict=True).decode for record in RECORDS.values()
}
_json_encode: Final = msgspec.json.Encoder().encode
_json_decode: Final = msgspec.json.Decoder(dict[str, Any]).decode


class _Typed(Protocol):
    """What :func:`decode` reads: an :class:`~objsearch.events.Event` or any event-like."""

    @property
    def type(self) -> str: ...
    @property
    def payload(self) -> Mapping[str, Any]: ...


def encode(record: Record) -> dict[str, Any]:
    """The payload dict of ``record`` (JSON types only: tuples become lists)."""
    # to_builtins keeps tuples; the JSON round trip (both halves in C) gives what a reader gets.
    payload: dict[str, Any] = _json_decode(_json_encode(record))
    return payload


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
        return msgspec.convert(
            payload if type(payload) is dict else dict(payload), record_type, strict=True
        )
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
        msgspec.convert(
            payload if type(payload) is dict else dict(payload), record_type, strict=True
        )
    except msgspec.ValidationError:
        return False
    return True


def _catalogue() -> Catalogue:
    return Catalogue(
        schemas=resources.files("objsearch.events").joinpath("schema"),
        upcasters=STEPS,
        accepts=accepts,
        derived=DERIVED_TABLES,
        schemas_checked=True,  # tests/events/test_schemas.py checks the shipped files
    )


#: The domain's catalogue: the schema files, the upcasters, the records' fast check and the
#: lake's Eq. 4 tables.
CATALOGUE: Final = _catalogue()
#: The product's store, the one value every reader and writer of the agent's events is handed
#: (``EventLog.open(..., store=STORE)``, ``read_log(dir, store=STORE)``, ``Lake(root,
#: store=STORE)``). Building it reads nothing: its schemas compile on first use.
STORE: Final = Store(CATALOGUE)
