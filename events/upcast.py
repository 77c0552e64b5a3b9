"""Upcasters: old event versions are rewritten to the latest on read, never on disk.

A released schema version is frozen, and so are the events written with it. When a type's payload
changes, its new schema gets the next version number and one *step* is registered here: a pure
function from a version-N payload to a version-N+1 payload. Reading chains the steps, so a v1
event reaches v3 through v1→v2→v3, and projections and the analytics lake only ever see the
latest version of each type (the pattern of the ``eventsourcing`` library's upcasting).

Tests check that every non-latest version of every schema has its step and that each step's
output validates against the next schema.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any, Final

from .envelope import Event
from .errors import EventStoreError
from .schemas import SchemaRegistry, default_registry

#: payload of version N (a fresh dict the step may keep) → payload of version N + 1
UpcastStep = Callable[[dict[str, Any]], dict[str, Any]]


def _detection_v1_to_v2(payload: dict[str, Any]) -> dict[str, Any]:
    # v1 had three loose fields that could disagree (a class without an id); v2 makes "the nearest
    # static object, or none" one nullable object.
    static_id = payload.pop("nearest_static_id")
    static_class = payload.pop("nearest_static_class")
    at_static = payload.pop("at_static")
    if static_id is None or static_class is None:
        payload["support"] = None
    else:
        payload["support"] = {"static_id": static_id, "static_class": static_class, "at": at_static}
    return payload


def _run_started_v1_to_v2(payload: dict[str, Any]) -> dict[str, Any]:
    # What a v1 run *was*, with the defaults of the code that wrote it. v1 recorded the method and
    # α; bench runs put the strategy's name in params; the Beta model's parameters were constants
    # of that code (prior strength 2, half-life 64 tasks) and are frozen here, so a v1 log folds
    # as it did whatever today's registry (objsearch.agent.strategies) says.
    params = dict(payload.pop("params"))
    name = params.pop("strategy", None)
    method = payload["method"]
    relations: dict[str, Any] = {"model": "eq4", "prior_strength": None, "half_life_tasks": None}
    if name in ("wpl-neg", "wpl-neg-decay", "epl-neg-decay"):
        half_life = None if name == "wpl-neg" else 64.0
        relations = {"model": "beta", "prior_strength": 2.0, "half_life_tasks": half_life}
    planner = "epl" if name in ("epl", "epl-neg-decay") or method == "epl" else method
    if method == "epl":  # v1 allowed it as a method; its rooms were ordered as WPL's
        payload["method"] = "wpl"
    payload["strategy"] = name if isinstance(name, str) else method
    payload["planner"] = planner
    payload["relations"] = relations
    radius = params.pop("support_radius", 0.5)
    payload["support_radius"] = float(radius) if isinstance(radius, int | float) else 0.5
    schedule = params.pop("schedule", None)
    payload["schedule"] = schedule if isinstance(schedule, str) else None
    payload["params"] = params
    return payload


def _run_started_v2_to_v3(payload: dict[str, Any]) -> dict[str, Any]:
    # v3 added a room order (ecost) and relation models (memory, dist-oracle) with one parameter
    # of their own; a v2 run used none of them.
    relations = dict(payload["relations"])
    relations["recent_weight"] = None
    payload["relations"] = relations
    return payload


#: (type, from_version) → step to from_version + 1. Append-only, like the schema files.
STEPS: Final[Mapping[tuple[str, int], UpcastStep]] = MappingProxyType(
    {
        ("detection", 1): _detection_v1_to_v2,
        ("run_started", 1): _run_started_v1_to_v2,
        ("run_started", 2): _run_started_v2_to_v3,
    }
)


class Upcaster:
    """Brings events to their type's latest schema version by chaining registered steps."""

    def __init__(
        self, registry: SchemaRegistry, steps: Mapping[tuple[str, int], UpcastStep]
    ) -> None:
        self._latest = {t: registry.latest_version(t) for t in registry.types}
        self._steps = dict(steps)
        for event_type, latest in self._latest.items():
            for version in registry.versions(event_type):
                if version < latest and (event_type, version) not in self._steps:
                    raise EventStoreError(
                        f"no upcaster for {event_type} v{version} → v{version + 1}; "
                        f"every version below the latest (v{latest}) needs one"
                    )

    def latest_version(self, event_type: str) -> int | None:
        return self._latest.get(event_type)

    def upcast_payload(
        self, event_type: str, version: int, payload: Mapping[str, Any]
    ) -> tuple[int, Any]:
        """(version, payload) brought to the latest version; unknown types pass through."""
        latest = self._latest.get(event_type, version)
        if version >= latest:
            return version, payload
        current = _plain(payload)
        while version < latest:
            current = self._steps[event_type, version](current)
            version += 1
        return version, current

    def upcast(self, event: Event) -> Event:
        """``event`` as its type's latest version (the same object if it already is)."""
        latest = self._latest.get(event.type)
        if latest is None or event.version >= latest:
            return event
        version, payload = self.upcast_payload(event.type, event.version, event.payload)
        return Event(
            event_id=event.event_id,
            stream=event.stream,
            seq=event.seq,
            time_ns=event.time_ns,
            recorded_at_ns=event.recorded_at_ns,
            type=event.type,
            version=version,
            task_id=event.task_id,
            payload=payload,
        )


def _plain(value: Any) -> Any:
    """A deep copy into plain dicts and lists (payloads are read-only mapping proxies)."""
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value


@functools.cache
def default_upcaster() -> Upcaster:
    """The package's steps over the package's schemas, built once per process."""
    return Upcaster(default_registry(), STEPS)
