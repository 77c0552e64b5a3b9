"""Hypothesis strategies for payloads valid under one of the catalogue's JSON Schemas.

The schemas use a small part of JSON Schema (``type``, ``enum``, ``properties`` / ``required`` /
``additionalProperties``, ``items`` / ``minItems`` / ``maxItems``, ``minimum`` / ``maximum`` /
``exclusiveMinimum``, ``$ref`` into ``$defs``, ``oneOf``); this builds a strategy from exactly that
part and fails loudly on any other keyword, so a schema that grows one is noticed here rather than
silently generating fewer cases. Every drawn payload is then checked by the registry's validator in
the tests, so a mistake here can only narrow what is tried, never let an invalid payload through.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from hypothesis import strategies as st

#: Keys a free-form object (``"type": "object"`` with no properties: ``params``) is drawn from:
#: those old upcasters read out of it, and others they must carry through untouched.
FREE_FORM_KEYS = ("strategy", "support_radius", "schedule", "fov_deg", "nested", "x")

_HANDLED = frozenset(
    {
        "$schema",
        "$id",
        "$defs",
        "$ref",
        "title",
        "description",
        "type",
        "enum",
        "properties",
        "required",
        "additionalProperties",
        "items",
        "minItems",
        "maxItems",
        "minimum",
        "maximum",
        "exclusiveMinimum",
        "oneOf",
    }
)

_JSON_SCALARS = (
    st.none()
    | st.booleans()
    | st.integers(-5, 5)
    | st.floats(-10, 10, allow_nan=False)
    | st.text(max_size=6)
)
_JSON = st.recursive(
    _JSON_SCALARS,
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3)
    ),
    max_leaves=6,
)


def payloads(schema: Mapping[str, Any]) -> st.SearchStrategy[Any]:
    """Values the JSON Schema ``schema`` (a whole schema file, its ``$defs`` resolvable) allows."""
    return _node(schema, schema)


def _node(node: Mapping[str, Any], root: Mapping[str, Any]) -> st.SearchStrategy[Any]:
    unknown = set(node) - _HANDLED
    if unknown:
        raise ValueError(f"schema keyword(s) this generator does not know: {sorted(unknown)}")
    if "$ref" in node:
        name = str(node["$ref"]).removeprefix("#/$defs/")
        return _node(root["$defs"][name], root)
    if "oneOf" in node:
        return st.one_of([_node(option, root) for option in node["oneOf"]])
    if "enum" in node:
        return st.sampled_from(list(node["enum"]))
    kinds = node.get("type")
    if kinds is None:
        return _JSON
    if isinstance(kinds, list):
        return st.one_of([_node({**node, "type": kind}, root) for kind in kinds])
    return _typed(str(kinds), node, root)


def _typed(kind: str, node: Mapping[str, Any], root: Mapping[str, Any]) -> st.SearchStrategy[Any]:
    if kind == "null":
        return st.none()
    if kind == "boolean":
        return st.booleans()
    if kind == "string":
        return st.text(max_size=12)
    if kind in ("number", "integer"):
        return _number(kind, node)
    if kind == "array":
        items = _node(node.get("items", {}), root)
        return st.lists(items, min_size=node.get("minItems", 0), max_size=node.get("maxItems", 4))
    if kind == "object":
        return _object(node, root)
    raise ValueError(f"schema type this generator does not know: {kind!r}")


def _number(kind: str, node: Mapping[str, Any]) -> st.SearchStrategy[Any]:
    low = node.get("minimum")
    high = node.get("maximum")
    above = node.get("exclusiveMinimum")
    if kind == "integer":
        lowest = low if low is not None else (math.floor(above) + 1 if above is not None else -1000)
        return st.integers(lowest, high if high is not None else 1000)
    lower = low if low is not None else above if above is not None else -1e6
    return st.floats(
        lower,
        high if high is not None else 1e6,
        exclude_min=above is not None and low is None,
        allow_nan=False,
        allow_infinity=False,
    ) | (
        st.integers(math.ceil(lower) + (above is not None), 1000) if high is None else st.nothing()
    )


def _object(node: Mapping[str, Any], root: Mapping[str, Any]) -> st.SearchStrategy[Any]:
    properties: Mapping[str, Any] = node.get("properties", {})
    if not properties:  # free-form: whatever JSON, including keys old code read out of it
        return st.dictionaries(
            st.sampled_from(FREE_FORM_KEYS) | st.text(max_size=4), _JSON, max_size=4
        )
    required = set(node.get("required", ()))
    fields = {name: _node(sub, root) for name, sub in properties.items()}
    optional = [name for name in fields if name not in required]

    @st.composite
    def draw(draw_: st.DrawFn) -> dict[str, Any]:
        present = [name for name in optional if draw_(st.booleans())]
        return {name: draw_(fields[name]) for name in fields if name in required or name in present}

    return draw()
