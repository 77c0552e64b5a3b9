"""Upcasters: old event versions are rewritten to the latest on read, never on disk.

A released schema version is frozen, and so are the events written with it. When a type's payload
changes, its new schema gets the next version number and the domain's catalogue registers one
*step* (:class:`objsearch.events.catalogue.Catalogue`): a pure function from a version-N payload to a
version-N+1 payload. Reading chains the steps, so a v1
event reaches v3 through v1→v2→v3, and projections and the analytics lake only ever see the
latest version of each type (the pattern of the ``eventsourcing`` library's upcasting).

Tests check that every non-latest version of every schema has its step and that each step's
output validates against the next schema.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from .catalogue import UpcastStep
from .envelope import Event
from .errors import EventStoreError
from .schemas import SchemaRegistry


class Upcaster:
    """Brings events to their type's latest schema version by chaining registered steps."""

    def __init__(
        self,
        registry: SchemaRegistry,
        steps: Mapping[tuple[str, int], UpcastStep],
        *,
        partial: bool = False,
    ) -> None:
        """Every version below its type's latest needs a step, unless ``partial``: then a missing
        step is an error when an event of that version is read (a store of schemas alone)."""
        self._latest = {t: registry.latest_version(t) for t in registry.types}
        self._steps = dict(steps)
        for event_type, latest in self._latest.items():
            for version in registry.versions(event_type):
                if not partial and version < latest and (event_type, version) not in self._steps:
                    raise EventStoreError(_missing(event_type, version, latest))

    @property
    def latest_versions(self) -> Mapping[str, int]:
        """Each known type's latest version."""
        return self._latest

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
            step = self._steps.get((event_type, version))
            if step is None:
                raise EventStoreError(
                    f"{_missing(event_type, version, latest)}: this store was built without the "
                    "domain's upcasters (read with the product's store, "
                    "objsearch.agent.catalogue.STORE)"
                )
            current = step(current)
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


def _missing(event_type: str, version: int, latest: int) -> str:
    return (
        f"no upcaster for {event_type} v{version} → v{version + 1}; "
        f"every version below the latest (v{latest}) needs one"
    )
