"""Upcast steps of the domain's events: a version-N payload → the version-N+1 payload.

Steps are pure functions on plain dicts (the store deep-copies the payload first) and are
append-only, like the schema files: a released version's step never changes. The store chains
them on read (:class:`objsearch.events.upcast.Upcaster`), so readers only see latest versions.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, Final

from objsearch.events.catalogue import UpcastStep


def detection_v1_to_v2(payload: dict[str, Any]) -> dict[str, Any]:
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


def detection_v2_to_v3(payload: dict[str, Any]) -> dict[str, Any]:
    # v3 records the detector's score and class distribution; before it the simulator's detector
    # was perfect (score 1, one class), and an accepted detection was one above the mask threshold.
    payload["score"] = 1.0
    payload["classes"] = []
    return payload


def run_started_v1_to_v2(payload: dict[str, Any]) -> dict[str, Any]:
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
    # v1 took any number; a negative radius held nothing "at" a static, as a radius of 0 does
    # (no object is at distance 0 or less), and today's schema allows no negative one.
    payload["support_radius"] = max(0.0, float(radius)) if isinstance(radius, int | float) else 0.5
    schedule = params.pop("schedule", None)
    payload["schedule"] = schedule if isinstance(schedule, str) else None
    payload["params"] = params
    return payload


#: (type, from_version) → step to from_version + 1. Append-only, like the schema files.
def run_started_v2_to_v3(payload: dict[str, Any]) -> dict[str, Any]:
    # v3 added a room order (ecost) and relation models (memory, dist-oracle) with one parameter
    # of their own; a v2 run used none of them.
    relations = dict(payload["relations"])
    relations["recent_weight"] = None
    payload["relations"] = relations
    return payload


def run_started_v3_to_v4(payload: dict[str, Any]) -> dict[str, Any]:
    # v4 added a relation model (routine-belief); a v3 run used none of it.
    return payload


def run_started_v4_to_v5(payload: dict[str, Any]) -> dict[str, Any]:
    # v5 added a relation model (routine-pooled); a v4 run used none of it.
    return payload


def task_started_v1_to_v2(payload: dict[str, Any]) -> dict[str, Any]:
    # v2 records the time of day a search began; a v1 search's is unknown.
    payload["clock"] = None
    return payload


def view_taken_v1_to_v2(payload: dict[str, Any]) -> dict[str, Any]:
    # v2 records the camera's tilt; before it the camera was always level.
    return {"pose": payload["pose"], "pitch": 0.0, **payload}


STEPS: Final[Mapping[tuple[str, int], UpcastStep]] = MappingProxyType(
    {
        ("detection", 1): detection_v1_to_v2,
        ("detection", 2): detection_v2_to_v3,
        ("run_started", 1): run_started_v1_to_v2,
        ("run_started", 2): run_started_v2_to_v3,
        ("run_started", 3): run_started_v3_to_v4,
        ("run_started", 4): run_started_v4_to_v5,
        ("task_started", 1): task_started_v1_to_v2,
        ("view_taken", 1): view_taken_v1_to_v2,
    }
)
