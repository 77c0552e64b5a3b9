"""The catalogue a store is built from: which event types exist and how old versions are read.

``events/`` knows no robot. A domain describes its events with a :class:`Catalogue` — the folder
of ``<type>.v<version>.json`` schemas, the upcast steps from each old version to the next,
optionally a fast check that accepts valid payloads without ``jsonschema``, and the per-run
tables the lake derives from its events — and builds a :class:`~objsearch.events.store.Store`
from it, which it hands to the log, ``read_log``, snapshots and the lake. Nothing is installed
process-wide. The product's catalogue is :data:`objsearch.agent.catalogue.CATALOGUE`.

This module imports nothing else of ``objsearch.events``: every other module of the store may
import it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any, NamedTuple

import msgspec

#: payload of version N (a fresh dict the step may keep) → payload of version N + 1
UpcastStep = Callable[[dict[str, Any]], dict[str, Any]]
#: (type, version, payload) → True if the payload is certainly valid; False lets the JSON Schema
#: decide (and word the error). Must never say True for a payload the schema rejects.
PayloadCheck = Callable[[str, int, Mapping[str, Any]], bool]

#: The folder of a run's derived files (``RUN/_derived/<name>.v<version>.parquet``).
DERIVED_DIR = "_derived"


class DerivedTable(NamedTuple):
    """A per-run table the lake writes beside a committed run's events (see ``derived.py``)."""

    name: str
    version: int
    sql: str  # over the per-type views; returns robot, date, run and the table's columns
    order_by: str  # the rows' order in the file (an ORDER BY clause over the table's columns)

    @property
    def file_name(self) -> str:
        return f"{self.name}.v{self.version}.parquet"

    def path(self, run_dir: Path) -> Path:
        return run_dir / DERIVED_DIR / self.file_name


@dataclass(frozen=True)
class Catalogue:
    """A domain's event types: schema files, upcasters, an optional fast payload check, and the
    per-run tables the lake derives from them besides ``searches`` (in dependency order).

    ``records``: the payload type of each (type, version) the domain writes, when it defines its
    payloads as ``msgspec.Struct``s: then they are the one definition and the schema files are
    written from them (:mod:`objsearch.events.schema_writer`). An old version no record defines
    but an upcast step starts from is a released schema file, kept as it was released."""

    schemas: Path | Traversable
    upcasters: Mapping[tuple[str, int], UpcastStep] = field(default_factory=dict)
    accepts: PayloadCheck | None = None
    derived: tuple[DerivedTable, ...] = ()
    records: Mapping[tuple[str, int], type[msgspec.Struct]] = field(default_factory=dict)
    #: The schema files ship with the package and the test suite checks them against the JSON
    #: Schema meta-schema: a process does not check them again (nor import jsonschema to).
    schemas_checked: bool = False
