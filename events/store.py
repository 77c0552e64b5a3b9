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
from collections.abc import Mapping
from importlib import resources
from types import MappingProxyType
from typing import Any, Final, NamedTuple

import msgspec

from .catalogue import Catalogue
from .envelope import ReadPayload, json_payload, require_mapping
from .errors import InvalidEventError
from .record_json import RecordCodec, record_codecs
from .schemas import SchemaRegistry
from .upcast import Upcaster

_PACKAGE: Final = __name__.rpartition(".")[0]


class Encoded(NamedTuple):
    """A payload the store has checked and encoded, ready for the log to frame and write
    (:meth:`Store.encode`, :meth:`Store.encode_record`)."""

    type: str
    version: int
    #: The payload's JSON as a record holds it (compact, sorted keys, UTF-8 left as is): a str
    #: from a dict, UTF-8 bytes from a typed record (msgspec's, framed as bytes: never decoded).
    text: str | bytes
    #: The payload the appended event carries: the checked copy (read-only), or the record's
    #: JSON decoded only when read (:class:`~objsearch.events.envelope.ReadPayload`).
    payload: Mapping[str, Any]


#: An :class:`Encoded` made from its four fields without ``NamedTuple.__new__``'s Python call
#: (once per append of a record).
_encoded: Final = functools.partial(tuple.__new__, Encoded)


class Store:
    """A catalogue and its compiled parts: the schema registry and the upcaster.

    Cheap to build (nothing is read or compiled until first asked for), immutable once built,
    and safe to share between threads.
    """

    __slots__ = ("_codecs", "_lock", "_registry", "_upcaster", "_writable", "catalogue")

    def __init__(self, catalogue: Catalogue) -> None:
        self.catalogue: Final = catalogue
        self._lock = threading.Lock()
        self._registry: SchemaRegistry | None = None
        self._upcaster: Upcaster | None = None
        self._codecs: dict[type[msgspec.Struct], RecordCodec] | None = None
        #: The codecs of records whose type and version the registry knows, as appends meet
        #: them (:meth:`encode_record`; a dict's item is set atomically, so threads may share it).
        self._writable: dict[type[msgspec.Struct], RecordCodec] = {}

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

    def encode(
        self, event_type: str, payload: Mapping[str, Any], version: int | None = None
    ) -> Encoded:
        """``payload`` of ``event_type`` v``version`` (default: the type's latest) checked
        against its schema and encoded: a deep copy in JSON types and its JSON text, made once
        (:func:`~objsearch.events.envelope.json_payload`). Raises :class:`InvalidEventError`
        naming what is wrong."""
        registry = self.registry
        if version is None:
            version = registry.latest_version(event_type)
        require_mapping(payload, event_type, version)
        copied, text = json_payload(payload, event_type, version)
        registry.validate(event_type, version, copied)
        return Encoded(event_type, version, text, MappingProxyType(copied))

    def encode_record(self, record: msgspec.Struct) -> Encoded:
        """A typed record of the catalogue (``Catalogue.records``) encoded: its type and version
        are the record's, and the text is what :meth:`encode` makes of its payload dict, made by
        msgspec without the dict (:mod:`.record_json`). A record msgspec would spell otherwise,
        or that does not fit its type, is encoded through its dict: :meth:`encode`'s
        normalisation, and its errors worded."""
        codec = self._writable.get(type(record))  # once per append: no method calls to find it
        if codec is None:
            codec = self.record_codec(type(record))
            if not self.registry.knows(codec.type, codec.version):
                return self.encode(codec.type, codec.payload(record), codec.version)
            self._writable[type(record)] = codec
        text = codec.payload_json(record)
        if text is not None:
            return _encoded((codec.type, codec.version, text, ReadPayload(text)))
        return self.encode(codec.type, codec.payload(record), codec.version)

    def __repr__(self) -> str:
        return f"Store({self.catalogue.schemas!s})"


@functools.cache
def shipped() -> Store:
    """The store of the schema files shipped in ``objsearch.events/schema/`` and nothing else."""
    return Store(
        Catalogue(schemas=resources.files(_PACKAGE).joinpath("schema"), schemas_checked=True)
    )
