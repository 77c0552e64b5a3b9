"""Payload schemas: one JSON Schema (draft 2020-12) per event type and version.

The files live in ``events/schema/<type>.v<version>.json``, written from the catalogue's records
(:mod:`objsearch.events.schema_writer`, ``make schemas``). A released version is frozen: a
change of meaning gets a new file (``.v2``), so every event on disk keeps the schema it was
validated against. Each file is self-contained (shared shapes like ``pose`` are copied into its
own ``$defs``) so that editing one schema can never change the meaning of another.
"""

from __future__ import annotations

import copy
import json
import re
from collections.abc import Iterable, Mapping
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from .catalogue import PayloadCheck
from .envelope import Event
from .errors import EventStoreError, InvalidEventError

if TYPE_CHECKING:
    from jsonschema import Draft202012Validator

_FILE_NAME: Final = re.compile(r"(?P<type>[a-z][a-z0-9_]*)\.v(?P<version>[1-9][0-9]*)\.json")


def schema_id(event_type: str, version: int) -> str:
    """The ``$id`` a schema file must declare; checked so a copied file can't lie about itself."""
    return f"urn:objsearch:events:{event_type}:v{version}"


def check_schema(schema: Mapping[str, Any], where: str) -> None:
    """``EventStoreError`` unless ``schema`` is a valid JSON Schema (draft 2020-12)."""
    # Here, not at the top: importing the store must not cost jsonschema's import (a tenth of a
    # CPU-second) to a process that never checks a schema (``objsearch --help``, a search).
    from jsonschema import Draft202012Validator
    from jsonschema.exceptions import SchemaError

    try:
        Draft202012Validator.check_schema(schema)
    except SchemaError as exc:
        raise EventStoreError(f"{where} is not a valid JSON Schema: {exc.message}") from exc


class SchemaRegistry:
    """All known (type, version) schemas, with compiled validators."""

    def __init__(
        self,
        schemas: Mapping[tuple[str, int], Mapping[str, Any]],
        *,
        accepts: PayloadCheck | None = None,
        checked: bool = False,
    ) -> None:
        """``checked``: the schemas were already checked against the JSON Schema meta-schema
        (the package's own files, which the test suite checks): not again here, so a process
        pays for jsonschema only if a payload needs it (the fast check did not vouch for it)."""
        self._accepts = accepts
        self._schemas: dict[tuple[str, int], dict[str, Any]] = {}
        self._validators: dict[tuple[str, int], Draft202012Validator] = {}
        self._latest: dict[str, int] = {}
        for (event_type, version), schema in sorted(schemas.items()):
            where = f"schema {event_type} v{version}"
            if schema.get("$id") != schema_id(event_type, version):
                raise EventStoreError(
                    f"{where}: $id is {schema.get('$id')!r}, expected "
                    f"{schema_id(event_type, version)!r}"
                )
            if not checked:
                check_schema(schema, where)
            if schema.get("type") != "object":
                raise EventStoreError(f"{where}: a payload schema must have type 'object'")
            self._schemas[event_type, version] = copy.deepcopy(dict(schema))
            self._latest[event_type] = max(version, self._latest.get(event_type, 0))
        self._known = frozenset(self._schemas)

    @classmethod
    def from_directory(
        cls,
        directory: Path | Traversable,
        *,
        accepts: PayloadCheck | None = None,
        checked: bool = False,
    ) -> SchemaRegistry:
        """Load each ``<type>.v<version>.json`` file; other ``*.json`` names are errors."""
        schemas: dict[tuple[str, int], dict[str, Any]] = {}
        for entry in sorted(directory.iterdir(), key=lambda e: e.name):
            if not entry.name.endswith(".json"):
                continue
            match = _FILE_NAME.fullmatch(entry.name)
            if match is None:
                raise EventStoreError(
                    f"schema file {entry.name!r} in {directory} is not named "
                    "<type>.v<version>.json (lower-case type, version >= 1)"
                )
            try:
                schema = json.loads(entry.read_text(encoding="utf-8"))
            except ValueError as exc:
                raise EventStoreError(
                    f"schema file {entry.name!r} is not valid JSON: {exc}"
                ) from exc
            if not isinstance(schema, dict):
                raise EventStoreError(f"schema file {entry.name!r} is not a JSON object")
            schemas[match["type"], int(match["version"])] = schema
        return cls(schemas, accepts=accepts, checked=checked)

    @property
    def known(self) -> frozenset[tuple[str, int]]:
        """Every (type, version) this registry has a schema for."""
        return self._known

    @property
    def types(self) -> tuple[str, ...]:
        return tuple(sorted(self._latest))

    def versions(self, event_type: str) -> tuple[int, ...]:
        self._require_type(event_type)
        return tuple(sorted(v for t, v in self._schemas if t == event_type))

    def knows(self, event_type: str, version: int) -> bool:
        """Whether this registry has a schema for ``event_type`` at ``version``."""
        return (event_type, version) in self._schemas

    def latest_version(self, event_type: str) -> int:
        self._require_type(event_type)
        return self._latest[event_type]

    def schema(self, event_type: str, version: int) -> dict[str, Any]:
        """A copy of the schema (callers may not change the registry's)."""
        return copy.deepcopy(self._schemas[self._require(event_type, version)])

    def validate(self, event_type: str, version: int, payload: Mapping[str, Any]) -> None:
        """Raise :class:`InvalidEventError` unless ``payload`` matches the schema.

        ``payload`` must hold plain JSON types (as :class:`Event` normalises them to): jsonschema
        does not count a tuple as an array.
        """
        key = self._require(event_type, version)
        instance = payload if isinstance(payload, dict) else dict(payload)
        # The catalogue's fast check (typed records) vouches for most payloads; the schema has
        # the last word on the rest and words the error.
        if self._accepts is not None and self._accepts(event_type, version, instance):
            return
        from jsonschema import Draft202012Validator
        from jsonschema.exceptions import best_match

        validator = self._validators.get(key)
        if validator is None:  # compiled on first need (here, not at start: see __init__)
            validator = self._validators[key] = Draft202012Validator(self._schemas[key])
        errors = list(validator.iter_errors(instance))
        if not errors:
            return
        error = best_match(errors)
        path = _json_path("payload", error.absolute_path)
        more = f" (and {len(errors) - 1} more problem(s))" if len(errors) > 1 else ""
        raise InvalidEventError(
            f"invalid {event_type} v{version} event: {path}: {error.message}{more}",
            event_type=event_type,
            version=version,
            path=path,
            reason=error.message,
        )

    def validate_event(self, event: Event) -> None:
        """Validate an event's payload (its envelope was checked when it was built)."""
        self.validate(event.type, event.version, event.payload)

    def _require_type(self, event_type: str) -> None:
        if event_type not in self._latest:
            known = ", ".join(self.types) or "(none)"
            raise InvalidEventError(
                f"unknown event type {event_type!r}; known types: {known}",
                event_type=event_type,
                reason="unknown type",
            )

    def _require(self, event_type: str, version: int) -> tuple[str, int]:
        self._require_type(event_type)
        key = (event_type, version)
        if key not in self._schemas:
            known = ", ".join(map(str, self.versions(event_type)))
            raise InvalidEventError(
                f"unknown version {version!r} of event type {event_type!r}; "
                f"known versions: {known}",
                event_type=event_type,
                version=version if isinstance(version, int) else None,
                reason="unknown version",
            )
        return key


def _json_path(root: str, parts: Iterable[str | int]) -> str:
    path = root
    for part in parts:
        path += f"[{part}]" if isinstance(part, int) else f".{part}"
    return path
