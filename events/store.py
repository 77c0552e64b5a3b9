"""The store value: a catalogue and what the event store compiles from it, handed to every reader
and writer.

``events/`` knows no robot. A domain describes its events with a
:class:`~objsearch.events.catalogue.Catalogue` and builds one :class:`Store` from it; that value
is passed to the log (``EventLog.open(..., store=)``), ``read_log``, snapshots, the Arrow export
and the lake — the way ``eventsourcing`` hands an application its mapper. Nothing is installed
anywhere and no import has a side effect: two stores with different catalogues live side by side
in one process, and each compiles its schemas, upcasters and Arrow schemas once, on first use.

The product's store is :data:`objsearch.agent.catalogue.STORE`. Every reader and writer takes
its store as a required argument: none falls back to a bare one. :func:`shipped` is the store a
caller may name on purpose: the schema files in ``objsearch.events/schema/`` alone, with no
upcasters (reading an old version is then an error that says so), no fast payload check (the
JSON Schema validates every append) and no derived tables besides ``searches``.
"""

from __future__ import annotations

import functools
import threading
from importlib import resources
from typing import Final

import msgspec

from .catalogue import Catalogue
from .errors import InvalidEventError
from .record_json import RecordCodec, record_codecs
from .schemas import SchemaRegistry
from .upcast import Upcaster

_PACKAGE: Final = __name__.rpartition(".")[0]


class Store:
    """A catalogue and its compiled parts: the schema registry and the upcaster.

    Cheap to build (nothing is read or compiled until first asked for), immutable once built,
    and safe to share between threads.
    """

    __slots__ = ("_codecs", "_lock", "_registry", "_upcaster", "catalogue")

    def __init__(self, catalogue: Catalogue) -> None:
        self.catalogue: Final = catalogue
        self._lock = threading.Lock()
        self._registry: SchemaRegistry | None = None
        self._upcaster: Upcaster | None = None
        self._codecs: dict[type[msgspec.Struct], RecordCodec] | None = None

    @property
    def registry(self) -> SchemaRegistry:
        """The catalogue's schemas with compiled validators (and its fast check)."""
        registry = self._registry
        if registry is None:
            with self._lock:
                if self._registry is None:
                    self._registry = SchemaRegistry.from_directory(
                        self.catalogue.schemas,
                        accepts=self.catalogue.accepts,
                        checked=self.catalogue.schemas_checked,
                    )
                registry = self._registry
        return registry

    @property
    def upcaster(self) -> Upcaster:
        """The catalogue's upcast steps over its schemas (every old version needs one, unless the
        catalogue has none at all: then an old version is an error when it is read)."""
        upcaster = self._upcaster
        if upcaster is None:
            registry = self.registry
            with self._lock:
                if self._upcaster is None:
                    self._upcaster = Upcaster(
                        registry, self.catalogue.upcasters, partial=not self.catalogue.upcasters
                    )
                upcaster = self._upcaster
        return upcaster

    def record_codec(self, record_type: type[msgspec.Struct]) -> RecordCodec:
        """The codec of one of the catalogue's records (``Catalogue.records``);
        :class:`InvalidEventError` for any other type."""
        codecs = self._codecs
        if codecs is None:
            codecs = self._codecs = record_codecs(self.catalogue.records)
        codec = codecs.get(record_type)
        if codec is None:
            raise InvalidEventError(
                f"{record_type.__name__} is not a record of this store's catalogue",
                reason="not a record of the catalogue",
            )
        return codec

    def __repr__(self) -> str:
        return f"Store({self.catalogue.schemas!s})"


@functools.cache
def shipped() -> Store:
    """The store of the schema files shipped in ``objsearch.events/schema/`` and nothing else."""
    return Store(
        Catalogue(schemas=resources.files(_PACKAGE).joinpath("schema"), schemas_checked=True)
    )
