"""Upcast chains as properties: *every* payload an old schema allows — not only the one example
per version in ``payloads.py`` — reads back as a valid latest payload, by the same chain however
it is entered, and the stored old payload is never changed."""

from __future__ import annotations

import copy
from typing import Any

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from objsearch.agent.catalogue import STORE
from objsearch.agent.upcasters import STEPS
from objsearch.events import Event, InvalidEventError

from .schema_payloads import payloads

OLD_VERSIONS = sorted(STEPS)
_SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _valid_old(event_type: str, version: int) -> st.SearchStrategy[Any]:
    schema = STORE.registry.schema(event_type, version)

    def valid(payload: Any) -> bool:
        try:
            STORE.registry.validate(event_type, version, payload)
        except InvalidEventError:
            return False
        return True

    return payloads(schema).filter(valid)


@pytest.mark.parametrize("key", OLD_VERSIONS, ids=[f"{t}-v{v}" for t, v in OLD_VERSIONS])
@_SETTINGS
@given(data=st.data())
def test_every_valid_old_payload_upcasts_to_a_valid_latest_one(
    key: tuple[str, int], data: st.DataObject
) -> None:
    event_type, version = key
    payload = data.draw(_valid_old(event_type, version), label="old payload")
    kept = copy.deepcopy(payload)
    latest, upcast = STORE.upcaster.upcast_payload(event_type, version, payload)
    assert latest == STORE.registry.latest_version(event_type)
    STORE.registry.validate(event_type, latest, upcast)
    assert payload == kept  # the stored payload is read, never rewritten


@pytest.mark.parametrize("key", OLD_VERSIONS, ids=[f"{t}-v{v}" for t, v in OLD_VERSIONS])
@_SETTINGS
@given(data=st.data())
def test_a_chain_entered_one_step_later_ends_in_the_same_payload(
    key: tuple[str, int], data: st.DataObject
) -> None:
    """upcast(v) = upcast(v + 1) ∘ step(v): each step's output is a valid input of the next, so a
    log holding a mix of versions reads the same whichever version each event was written at."""
    event_type, version = key
    payload = data.draw(_valid_old(event_type, version), label="old payload")
    one_step = STEPS[key](copy.deepcopy(payload))
    STORE.registry.validate(event_type, version + 1, one_step)
    assert (
        STORE.upcaster.upcast_payload(event_type, version + 1, one_step)[1]
        == STORE.upcaster.upcast_payload(event_type, version, payload)[1]
    )


@_SETTINGS
@given(data=st.data())
def test_an_event_read_at_its_latest_version_is_left_alone(data: st.DataObject) -> None:
    event_type = data.draw(st.sampled_from(sorted(STORE.registry.types)), label="type")
    latest = STORE.registry.latest_version(event_type)
    payload = data.draw(payloads(STORE.registry.schema(event_type, latest)), label="payload")
    try:
        STORE.registry.validate(event_type, latest, payload)
    except InvalidEventError:
        assume(False)
    event = Event(
        seq=1,
        event_id="00000000-0000-0000-0000-000000000001",
        stream="s",
        type=event_type,
        version=latest,
        time_ns=0,
        recorded_at_ns=0,
        task_id=None,
        payload=payload,
    )
    assert STORE.upcaster.upcast(event) is event


@_SETTINGS
@given(payload=_valid_old("detection", 1))
def test_a_v1_detection_keeps_its_static_exactly_when_it_named_one(payload: dict[str, Any]) -> None:
    support = STORE.upcaster.upcast_payload("detection", 1, payload)[1]["support"]
    if payload["nearest_static_id"] is None or payload["nearest_static_class"] is None:
        assert support is None
    else:
        assert support == {
            "static_id": payload["nearest_static_id"],
            "static_class": payload["nearest_static_class"],
            "at": payload["at_static"],
        }
