"""The payload schema files, written from the catalogue's records.

A catalogue's records (``msgspec.Struct`` types, one per event type and version it writes) are
the one definition of its payloads; ``<type>.v<version>.json`` in its schema folder is generated
from them, never edited. An old version no record defines (one an upcast step starts from) is a
released file: kept byte for byte as it was released, the definition of that version. Each file is self-contained: every nested struct is copied into its own
``$defs``, so changing one file can never change the meaning of another.

What a record says and what its file says:

* every field is required and no other is allowed (``additionalProperties: false``), at every
  level; a ``dict[str, Any]`` field is a free-form object;
* ``str``, ``int``, ``float``, ``bool`` are ``string``, ``integer``, ``number``, ``boolean``; a
  ``Literal`` of strings is an ``enum``; ``msgspec.Meta``'s ``ge``/``gt``/``le``/``lt`` are
  ``minimum``/``exclusiveMinimum``/``maximum``/``exclusiveMaximum``;
* a fixed ``tuple[float, float]`` is an array of exactly that many items, ``tuple[T, ...]`` an
  array of ``T``;
* ``X | None`` adds ``null`` to X's type (``oneOf`` with ``null`` for a nested struct);
* a nested struct is ``$defs/<name>``: its ``SCHEMA_NAME`` class variable if it has one, else
  its class name in snake case;
* descriptions: a record's or nested struct's docstring, a field's
  ``msgspec.Meta(description=...)``; whitespace runs become one space.

``tests/events/test_schemas.py`` holds the committed files equal to :func:`render`'s bytes.
"""

from __future__ import annotations

import json
import re
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Final

import msgspec

from .catalogue import Catalogue
from .schemas import schema_id

DRAFT: Final = "https://json-schema.org/draft/2020-12/schema"
#: The order of keywords in a written schema object (others follow, sorted).
_KEY_ORDER: Final = (
    "$schema",
    "$id",
    "title",
    "description",
    "$ref",
    "oneOf",
    "type",
    "enum",
    "items",
    "minItems",
    "maxItems",
    "minimum",
    "exclusiveMinimum",
    "maximum",
    "exclusiveMaximum",
    "additionalProperties",
    "required",
    "properties",
    "$defs",
)
_RANK: Final = {key: i for i, key in enumerate(_KEY_ORDER)}


class SchemaWriterError(Exception):
    """A record uses a type the schema writer does not translate (say which, and where)."""


def file_name(event_type: str, version: int) -> str:
    return f"{event_type}.v{version}.json"


def schema_of(record: type[msgspec.Struct], event_type: str, version: int) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of ``record``, the payload of ``event_type`` v``version``."""
    defs: dict[str, dict[str, Any]] = {}
    root: dict[str, Any] = {
        "$schema": DRAFT,
        "$id": schema_id(event_type, version),
        "title": f"{event_type} v{version}",
        **_struct(record, defs, f"{event_type} v{version}"),
    }
    if defs:
        root["$defs"] = defs
    return _ordered(root)


def released(catalogue: Catalogue) -> list[tuple[str, int]]:
    """The released old versions the catalogue keeps as files, not records: each version an
    upcast step starts from that no record defines. Their files are the definition: read from
    the catalogue's schema folder, never written from anything (a released version's meaning
    never changes)."""
    return sorted(key for key in catalogue.upcasters if key not in catalogue.records)


def render(catalogue: Catalogue) -> dict[str, bytes]:
    """Each schema file's name and bytes: written from the catalogue's records, and the released
    old versions' files (:func:`released`) as the catalogue's schema folder holds them."""
    if not catalogue.records:
        raise SchemaWriterError("the catalogue has no records to write schemas from")
    files = {
        file_name(event_type, version): _dump(schema_of(record, event_type, version))
        for (event_type, version), record in sorted(catalogue.records.items())
    }
    for event_type, version in released(catalogue):
        name = file_name(event_type, version)
        source = catalogue.schemas.joinpath(name)
        if not source.is_file():
            raise SchemaWriterError(
                f"{name}: a released version (an upcast step starts from it) whose file is not "
                f"in {catalogue.schemas}; restore it from version control, it is never rewritten"
            )
        files[name] = source.read_bytes()
    return dict(sorted(files.items()))


def differences(catalogue: Catalogue, directory: Path) -> list[str]:
    """The schema files in ``directory`` that are not what :func:`render` writes: changed,
    missing, or there without a record or a released version (empty if the folder is up to
    date)."""
    wanted = render(catalogue)
    kept = {file_name(*key) for key in released(catalogue)}

    def source(name: str) -> str:
        return "released file" if name in kept else "record"

    out = []
    for name, data in wanted.items():
        path = directory / name
        if not path.is_file():
            out.append(f"{name}: missing")
        elif path.read_bytes() != data:
            out.append(f"{name}: differs from its {source(name)}")
    out += [
        f"{path.name}: no record defines it"
        for path in sorted(directory.glob("*.json"))
        if path.name not in wanted
    ]
    return out


def write(catalogue: Catalogue, directory: Path) -> list[str]:
    """Write every schema file into ``directory`` and delete ``*.json`` files no record defines;
    returns the names written or deleted (those that changed)."""
    wanted = render(catalogue)
    changed = []
    for name, data in wanted.items():
        path = directory / name
        if not path.is_file() or path.read_bytes() != data:
            path.write_bytes(data)
            changed.append(name)
    for path in sorted(directory.glob("*.json")):
        if path.name not in wanted:
            path.unlink()
            changed.append(path.name)
    return changed


def _dump(schema: dict[str, Any]) -> bytes:
    return (json.dumps(schema, indent=2, ensure_ascii=False) + "\n").encode("utf-8")


def _description(doc: str | None) -> str | None:
    return " ".join(doc.split()) or None if doc else None


def _struct(cls: type[Any], defs: dict[str, dict[str, Any]], at: str) -> dict[str, Any]:
    if not (isinstance(cls, type) and issubclass(cls, msgspec.Struct)):
        raise SchemaWriterError(f"{at}: {cls!r} is not a msgspec.Struct")
    config = cls.__struct_config__
    if config.tag_field is not None or config.array_like:
        raise SchemaWriterError(f"{at}: tagged or array-like structs are not payloads")
    node: dict[str, Any] = {"type": "object"}
    description = _description(cls.__doc__)
    if description is not None:
        node["description"] = description
    fields = msgspec.structs.fields(cls)
    for field in fields:
        if not field.required:
            raise SchemaWriterError(f"{at}.{field.name}: has a default; every field is required")
    node["additionalProperties"] = False
    node["required"] = [f.encode_name for f in fields]
    node["properties"] = {
        f.encode_name: _node(f.type, defs, f"{at}.{f.encode_name}") for f in fields
    }
    return node


#: The ``msgspec.Meta`` constraints a schema states, and their keywords.
_BOUNDS: Final = (
    ("ge", "minimum"),
    ("gt", "exclusiveMinimum"),
    ("le", "maximum"),
    ("lt", "exclusiveMaximum"),
)
_UNTRANSLATED: Final = ("multiple_of", "pattern", "min_length", "max_length", "extra_json_schema")


def _node(hint: Any, defs: dict[str, dict[str, Any]], at: str) -> dict[str, Any]:
    """The schema of one type annotation (a struct's field, or a part of one)."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is typing.Annotated:
        node = _node(args[0], defs, at)
        for meta in hint.__metadata__:
            if not isinstance(meta, msgspec.Meta):
                continue
            for name in _UNTRANSLATED:
                if getattr(meta, name) is not None:
                    raise SchemaWriterError(f"{at}: msgspec.Meta({name}=...) is not translated")
            for name, keyword in _BOUNDS:
                if getattr(meta, name) is not None:
                    node[keyword] = getattr(meta, name)
            if meta.description is not None:
                node["description"] = _description(meta.description)
        return _ordered(node)
    if origin is typing.Union or origin is types.UnionType:
        return _nullable(args, defs, at)
    if origin is typing.Literal:
        if not all(isinstance(v, str) for v in args):
            raise SchemaWriterError(f"{at}: only string literals are translated")
        return {"type": "string", "enum": list(args)}
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return {"type": "array", "items": _node(args[0], defs, f"{at}[]")}
        items = [_node(t, defs, at) for t in args]
        if not items or any(item != items[0] for item in items):
            raise SchemaWriterError(f"{at}: a fixed tuple must have one item type")
        return {"type": "array", "items": items[0], "minItems": len(items), "maxItems": len(items)}
    if origin is list:
        return {"type": "array", "items": _node(args[0], defs, f"{at}[]")}
    if origin is dict:
        if args != (str, Any):
            raise SchemaWriterError(f"{at}: only dict[str, Any] (free-form) is translated")
        return {"type": "object"}
    if hint is Any:
        return {}
    if hint is None or hint is type(None):
        return {"type": "null"}
    if isinstance(hint, type) and issubclass(hint, msgspec.Struct):
        return {"$ref": f"#/$defs/{_define(hint, defs, at)}"}
    if hint in _SCALARS:
        return {"type": _SCALARS[hint]}
    raise SchemaWriterError(f"{at}: {hint!r} is not translated to JSON Schema")


#: bool before int: ``bool`` is a subclass of ``int``, but the lookup is by identity.
_SCALARS: Final[Mapping[Any, str]] = {
    bool: "boolean",
    str: "string",
    int: "integer",
    float: "number",
}


def _nullable(args: tuple[Any, ...], defs: dict[str, dict[str, Any]], at: str) -> dict[str, Any]:
    others = [t for t in args if t is not type(None)]
    if len(others) != 1 or len(args) != 2:
        raise SchemaWriterError(f"{at}: only 'X | None' unions are translated")
    node = _node(others[0], defs, at)
    kind = node.get("type")
    if isinstance(kind, str) and "enum" not in node:
        return {**node, "type": [kind, "null"]}
    return {"oneOf": [{"type": "null"}, node]}


def _define(cls: type[msgspec.Struct], defs: dict[str, dict[str, Any]], at: str) -> str:
    name = getattr(cls, "SCHEMA_NAME", None) or _snake(cls.__name__)
    node = _ordered(_struct(cls, defs, at))
    if defs.get(name, node) != node:
        raise SchemaWriterError(f"{at}: two different structs are both $defs/{name}")
    defs[name] = node
    return str(name)


def _snake(name: str) -> str:
    return re.sub(r"(?<!^)(?=[A-Z])", "_", name).lower()


def _ordered(node: Mapping[str, Any]) -> dict[str, Any]:
    return {key: node[key] for key in sorted(node, key=lambda k: (_RANK.get(k, len(_RANK)), k))}
