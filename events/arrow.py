"""Typed Arrow tables of events, one per event type, derived from the payload JSON Schemas.

Each type's table has the envelope columns (``event_id``, ``stream``, ``seq``, ``time_ns``,
``recorded_at_ns``, ``version``, ``task_id``) followed by one column per payload field of the
type's *latest* schema version (older events are upcast first). JSON types map to Arrow types:
string/enum → string, number → float64, integer → int64, boolean → bool, array → list, object
with properties → struct, ``[T, "null"]`` and ``oneOf: [null, T]`` → nullable T. Nothing in the
analytic path is a JSON string, with one exception by design: an object the schema leaves
free-form (``run_started.params``) has no columns to give, so it is kept as compact JSON text.
"""

from __future__ import annotations

import contextlib
import functools
import json
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any, Final

import msgspec
import pyarrow as pa
import pyarrow.compute as pc

from .envelope import Event, ReadPayload, _Adopted, canonical_ids
from .errors import EventStoreError
from .schemas import SchemaRegistry
from .store import Store

ENVELOPE_COLUMNS: Final = (
    pa.field("event_id", pa.string(), nullable=False),
    pa.field("stream", pa.string(), nullable=False),
    pa.field("seq", pa.int64(), nullable=False),
    pa.field("time_ns", pa.int64(), nullable=False),
    pa.field("recorded_at_ns", pa.int64(), nullable=False),
    pa.field("version", pa.int32(), nullable=False),
    pa.field("task_id", pa.string()),
)
_ENVELOPE_NAMES: Final = frozenset(f.name for f in ENVELOPE_COLUMNS)
_ENVELOPE_ORDER: Final = (
    "event_id",
    "stream",
    "seq",
    "time_ns",
    "recorded_at_ns",
    "version",
    "task_id",
)


def arrow_type(node: Mapping[str, Any], root: Mapping[str, Any], where: str) -> pa.DataType:
    """The Arrow type of one JSON Schema node (``root`` resolves ``#/$defs/...`` references)."""
    if "$ref" in node:
        ref = node["$ref"]
        if not ref.startswith("#/$defs/"):
            raise EventStoreError(f"{where}: only local $defs references are supported ({ref})")
        return arrow_type(root["$defs"][ref.removeprefix("#/$defs/")], root, where)
    if "oneOf" in node:
        options = [o for o in node["oneOf"] if o.get("type") != "null"]
        if len(options) != 1:
            raise EventStoreError(f"{where}: oneOf must be [null, one schema] to have a column")
        return arrow_type(options[0], root, where)
    kind = node.get("type")
    if isinstance(kind, list):
        kinds = [k for k in kind if k != "null"]
        if len(kinds) != 1:
            raise EventStoreError(f"{where}: a union of {kind} has no single column type")
        kind = kinds[0]
    if kind == "string":
        return pa.string()
    if kind == "number":
        return pa.float64()
    if kind == "integer":
        return pa.int64()
    if kind == "boolean":
        return pa.bool_()
    if kind == "array":
        return pa.list_(arrow_type(node["items"], root, f"{where}[]"))
    if kind == "object":
        props = node.get("properties")
        if not props:
            return pa.string()  # free-form by design: compact JSON text (see module docstring)
        return pa.struct(
            [pa.field(name, arrow_type(p, root, f"{where}.{name}")) for name, p in props.items()]
        )
    if "enum" in node and all(isinstance(v, str) for v in node["enum"]):
        return pa.string()
    raise EventStoreError(f"{where}: JSON Schema node {dict(node)!r} has no Arrow type")


def payload_schema(schema: Mapping[str, Any], where: str) -> list[pa.Field]:
    fields = []
    for name, prop in schema["properties"].items():
        if name in _ENVELOPE_NAMES:
            raise EventStoreError(
                f"{where}: payload field {name!r} clashes with an envelope column"
            )
        fields.append(pa.field(name, arrow_type(prop, schema, f"{where}.{name}")))
    return fields


def event_schema(event_type: str, store: Store) -> pa.Schema:
    """The Arrow schema of ``event_type``'s table (its latest version in ``store``'s catalogue),
    built once per store."""
    return _event_schema(store.registry, event_type)


@functools.cache  # by registry identity: one per store, which lives as long as the process
def _event_schema(registry: SchemaRegistry, event_type: str) -> pa.Schema:
    version = registry.latest_version(event_type)
    schema = registry.schema(event_type, version)
    fields = payload_schema(schema, f"{event_type} v{version}")
    return pa.schema([*ENVELOPE_COLUMNS, *fields], metadata={"event_type": event_type})


def _free_form(value: Any, kind: pa.DataType) -> Any:
    if pa.types.is_string(kind) and isinstance(value, Mapping | list):
        return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=False)
    return value


def events_to_tables(events: Iterable[Event], store: Store) -> dict[str, pa.Table]:
    """One typed table per event type present, rows in seq order; events upcast to latest."""
    upcast = store.upcaster.upcast
    columns: dict[str, dict[str, list[Any]]] = {}
    schemas: dict[str, pa.Schema] = {}
    # Per type, once: (payload field, its column, whether it may hold free-form JSON text).
    payload_fields: dict[str, list[tuple[str, list[Any], bool]]] = {}
    for raw in events:
        event = upcast(raw)
        cols = columns.get(event.type)
        if cols is None:
            schema = schemas[event.type] = event_schema(event.type, store)
            cols = columns[event.type] = {name: [] for name in schema.names}
            payload_fields[event.type] = [
                (f.name, cols[f.name], pa.types.is_string(f.type))
                for f in schema
                if f.name not in _ENVELOPE_NAMES
            ]
        cols["event_id"].append(event.event_id)
        cols["stream"].append(event.stream)
        cols["seq"].append(event.seq)
        cols["time_ns"].append(event.time_ns)
        cols["recorded_at_ns"].append(event.recorded_at_ns)
        cols["version"].append(event.version)
        cols["task_id"].append(event.task_id)
        payload = event.payload
        for name, column, text in payload_fields[event.type]:
            value = payload[name]
            column.append(_free_form(value, pa.string()) if text else value)
    return {t: pa.Table.from_pydict(cols, schema=schemas[t]) for t, cols in sorted(columns.items())}


def tables_to_events(
    tables: Iterable[pa.Table], store: Store, *, records: bool = False
) -> list[Event]:
    """The inverse of :func:`events_to_tables`: events (latest versions) sorted by (stream, seq).

    Free-form objects come back from their JSON text; numbers come back as the column's type
    (a JSON integer in a ``number`` field reads as a float, which compares equal).

    ``records``: each event at its type's latest version also carries its typed record (the
    store's catalogue's), converted with the rest of its table in one call, on its payload (a
    :class:`ReadPayload`, as a log's event keeps the record a fold decodes), so every fold of
    it shares that one conversion. A payload that does not convert carries none (the fold
    that decodes it words the error, as it would have).
    """
    events: list[Event] = []
    tables = list(tables)
    new_payload = ReadPayload.__new__
    for table in tables:
        event_type = (table.schema.metadata or {}).get(b"event_type", b"").decode()
        if not event_type:
            raise EventStoreError("a lake table without its event_type metadata")
        free = _free_names(store.registry, event_type)
        # The payloads as Arrow's fresh dicts, lists and plain numbers, owned by no one else:
        # adopted, not deep-copied as Event(...) copies a caller's payload (that copy was most
        # of a lake run's read, 13 of 24 s for 300 k events).
        payloads = table.select(
            [n for n in table.column_names if n not in _ENVELOPE_NAMES]
        ).to_pylist()
        for name in free:
            for payload in payloads:
                value = payload[name]
                if isinstance(value, str):
                    payload[name] = json.loads(value)
        columns = [table.column(n).to_pylist() for n in _ENVELOPE_ORDER]
        made = (
            _records(store, event_type, payloads, columns[5]) if records else [None] * len(payloads)
        )
        # The envelope checked a column at a time (the ids with one regex, as a log's scan
        # does): then each event is built unchecked; otherwise each is checked, to word the error.
        checked = _envelope_holds(table) and canonical_ids(columns[0])
        for (
            event_id,
            stream,
            seq,
            time_ns,
            recorded_at_ns,
            version,
            task_id,
            payload,
            record,
        ) in zip(*columns, payloads, made, strict=True):
            if checked:
                wrapped: Mapping[str, Any]
                if records:  # ReadPayload.of(payload, record), inlined: one call less an event
                    read = new_payload(ReadPayload)
                    read._dict = payload
                    read.unread = None
                    read.record = record
                    wrapped = read
                else:
                    wrapped = MappingProxyType(payload)
                events.append(
                    _Adopted(
                        event_id=event_id,
                        stream=stream,
                        seq=seq,
                        time_ns=time_ns,
                        recorded_at_ns=recorded_at_ns,
                        type=event_type,
                        version=version,
                        task_id=task_id,
                        payload=wrapped,
                    )
                )
                continue
            events.append(
                Event._adopt(
                    {
                        "event_id": event_id,
                        "stream": stream,
                        "seq": seq,
                        "time_ns": time_ns,
                        "recorded_at_ns": recorded_at_ns,
                        "type": event_type,
                        "version": version,
                        "task_id": task_id,
                        "payload": payload,
                    }
                )
            )
    if len(tables) == 1 and _in_order(tables[0]):  # a lake slice's rows mostly are already
        return events
    return sorted(events, key=lambda e: (e.stream, e.seq))


def _in_order(table: pa.Table) -> bool:
    """Whether ``table``'s rows are in (stream, seq) order already: one stream, seq rising."""
    if table.num_rows < 2:
        return True
    stream, seq = table.column("stream"), table.column("seq")
    if stream.null_count or seq.null_count or pc.count_distinct(stream).as_py() != 1:
        return False
    values = seq.to_numpy()
    return bool((values[1:] > values[:-1]).all())


@functools.cache  # by registry identity, as _event_schema: a schema read deep-copies it
def _free_names(registry: SchemaRegistry, event_type: str) -> frozenset[str]:
    """The payload fields of ``event_type`` (its latest version) that are free-form objects,
    kept as JSON text."""
    schema = _event_schema(registry, event_type)
    return frozenset(
        f.name
        for f in schema
        if f.name not in _ENVELOPE_NAMES
        and pa.types.is_string(f.type)
        and _is_free(registry, event_type, f.name)
    )


def _records(
    store: Store, event_type: str, payloads: list[dict[str, Any]], versions: list[int]
) -> list[Any]:
    """The record of each payload at ``event_type``'s latest version (None for another version,
    one that does not convert, or a type the catalogue has no record of), as the domain's
    ``decode`` converts it (strict): the rows in one call, one at a time only if that fails."""
    latest = store.upcaster.latest_version(event_type)
    record_type = store.catalogue.records.get((event_type, latest or 0))
    if record_type is None:
        return [None] * len(payloads)
    if all(v == latest for v in versions):
        try:
            made: list[Any] = msgspec.convert(payloads, list[record_type], strict=True)  # type: ignore[valid-type]
            return made
        except msgspec.ValidationError:
            pass
    out: list[Any] = []
    for payload, version in zip(payloads, versions, strict=True):
        record = None
        if version == latest:
            with contextlib.suppress(msgspec.ValidationError):
                record = msgspec.convert(payload, record_type, strict=True)
        out.append(record)
    return out


def _envelope_holds(table: pa.Table) -> bool:
    """Whether every row's envelope keeps :class:`Event`'s rules but the id's spelling: ids of
    36 characters, a stream and a type, seq and version from 1, times from 0, a task id absent
    or not empty."""
    if table.num_rows == 0:
        return True
    required = ("event_id", "stream", "seq", "time_ns", "recorded_at_ns", "version")
    if any(table.column(n).null_count for n in required):
        return False
    lengths = pc.min_max(pc.utf8_length(table.column("event_id"))).as_py()
    least = {
        n: pc.min(table.column(n)).as_py() for n in ("seq", "time_ns", "recorded_at_ns", "version")
    }
    task = table.column("task_id")
    return bool(
        lengths == {"min": 36, "max": 36}
        and pc.min(pc.utf8_length(table.column("stream"))).as_py() >= 1
        and least["seq"] >= 1
        and least["version"] >= 1
        and least["time_ns"] >= 0
        and least["recorded_at_ns"] >= 0
        and (task.null_count == len(task) or pc.min(pc.utf8_length(task)).as_py() >= 1)
    )


def _is_free(registry: SchemaRegistry, event_type: str, field: str) -> bool:
    node = registry.schema(event_type, registry.latest_version(event_type))["properties"][field]
    return node.get("type") == "object" and not node.get("properties")
