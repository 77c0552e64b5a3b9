"""The catalogue the store is handed: which event types exist and how old versions are read.

``events/`` knows no robot. A domain describes its events with a :class:`Catalogue` — the folder
of ``<type>.v<version>.json`` schemas, the upcast steps from each old version to the next, and
optionally a fast check that accepts valid payloads without ``jsonschema`` — and installs it as
the process's default with :func:`install`. ``read_log(dir)``, ``EventLog.open(dir)``, the lake and
the Arrow export all use the installed catalogue (through :func:`~objsearch.events.default_registry`
and :func:`~objsearch.events.default_upcaster`), and the lake writes the catalogue's derived
tables beside each committed run (:func:`~objsearch.events.derived.derived_tables`), so no formula
of the domain's lives here. The ``objsearch`` package installs the agent's
catalogue (:data:`objsearch.agent.catalogue.CATALOGUE`) when it is imported, so callers never
have to; a test or another domain may install its own.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

if TYPE_CHECKING:
    # Only the annotation: derived.py imports installed() from here, so no import at run time.
    from .derived import DerivedTable

#: payload of version N (a fresh dict the step may keep) → payload of version N + 1
UpcastStep = Callable[[dict[str, Any]], dict[str, Any]]
#: (type, version, payload) → True if the payload is certainly valid; False lets the JSON Schema
#: decide (and word the error). Must never say True for a payload the schema rejects.
PayloadCheck = Callable[[str, int, Mapping[str, Any]], bool]

_PACKAGE: Final = __name__.rpartition(".")[0]


@dataclass(frozen=True)
class Catalogue:
    """A domain's event types: schema files, upcasters, an optional fast payload check, and the
    per-run tables the lake derives from them besides ``searches`` (in dependency order)."""

    schemas: Path | Traversable
    upcasters: Mapping[tuple[str, int], UpcastStep] = field(default_factory=dict)
    accepts: PayloadCheck | None = None
    derived: tuple[DerivedTable, ...] = ()


def schemas_only() -> Catalogue:
    """The schema files shipped in ``objsearch.events/schema/``, with no upcasters or check."""
    return Catalogue(schemas=resources.files(_PACKAGE).joinpath("schema"))


_installed: list[Catalogue] = []


def install(catalogue: Catalogue) -> None:
    """Make ``catalogue`` the default of every store function called without one."""
    from .schemas import default_registry
    from .upcast import default_upcaster

    _installed[:] = [catalogue]
    default_registry.cache_clear()
    default_upcaster.cache_clear()


def installed() -> Catalogue:
    """The installed catalogue (:func:`schemas_only` if none was)."""
    return _installed[0] if _installed else schemas_only()
