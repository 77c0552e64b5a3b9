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

import functools
import json
from collections.abc import Iterable, Mapping
from typing import Any, Final

import pyarrow as pa

from .envelope import Event
from .errors import EventStoreError
from .schemas import SchemaRegistry
from .store import Store, shipped

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


def event_schema(event_type: str, store: Store | None = None) -> pa.Schema:
    """The Arrow schema of ``event_type``'s table (its latest version in ``store``'s catalogue),
    built once per store."""
    return _event_schema((store or shipped()).registry, event_type)


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


def events_to_tables(events: Iterable[Event], store: Store | None = None) -> dict[str, pa.Table]:
    """One typed table per event type present, rows in seq order; events upcast to latest."""
    store = store or shipped()
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


def tables_to_events(tables: Iterable[pa.Table], store: Store | None = None) -> list[Event]:
    """The inverse of :func:`events_to_tables`: events (latest versions) sorted by (stream, seq).

    Free-form objects come back from their JSON text; numbers come back as the column's type
    (a JSON integer in a ``number`` field reads as a float, which compares equal).
    """
    store = store or shipped()
    events: list[Event] = []
    for table in tables:
        event_type = (table.schema.metadata or {}).get(b"event_type", b"").decode()
        if not event_type:
            raise EventStoreError("a lake table without its event_type metadata")
        schema = event_schema(event_type, store)
        free = {
            f.name
            for f in schema
            if f.name not in _ENVELOPE_NAMES
            and pa.types.is_string(f.type)
            and _is_free(store.registry, event_type, f.name)
        }
        for row in table.to_pylist():
            payload = {
                k: (json.loads(v) if k in free and isinstance(v, str) else v)
                for k, v in row.items()
                if k not in _ENVELOPE_NAMES
            }
            events.append(
                Event(
                    event_id=row["event_id"],
                    stream=row["stream"],
                    seq=row["seq"],
                    time_ns=row["time_ns"],
                    recorded_at_ns=row["recorded_at_ns"],
                    type=event_type,
                    version=row["version"],
                    task_id=row["task_id"],
                    payload=payload,
                )
            )
    return sorted(events, key=lambda e: (e.stream, e.seq))


def _is_free(registry: SchemaRegistry, event_type: str, field: str) -> bool:
    node = registry.schema(event_type, registry.latest_version(event_type))["properties"][field]
    return node.get("type") == "object" and not node.get("properties")
