"""Canonical JSON: a rebuild must be byte-identical (``events._fs.write_atomic`` keeps it whole)."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

DECIMALS = 4


def canonical(value: Any) -> Any:
    """Round floats to ``DECIMALS`` and turn tuples into lists, recursively.

    ``-0.0`` becomes ``0.0``: negating a Unity coordinate of 0 would otherwise leave ``-0.0`` in
    the files, which is equal but not byte-identical to what a reader expects.
    """
    if isinstance(value, bool) or value is None or isinstance(value, (int, str)):
        return value
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"non-finite number {value!r} cannot be written to derived data")
        return round(value, DECIMALS) + 0.0
    if isinstance(value, Mapping):
        return {str(k): canonical(v) for k, v in value.items()}
    if isinstance(value, Sequence):
        return [canonical(v) for v in value]
    raise TypeError(f"cannot write {type(value).__name__} to derived data")


def dumps(value: Any, *, inline_rows: bool = False) -> str:
    """Sorted keys, 2-space indent, rounded floats, trailing newline.

    ``inline_rows`` writes every list of scalars on one line: a table of many short rows
    (the rearrangement placements) stays diff-able and a fifth of the size.
    """
    value = canonical(value)
    if not inline_rows:
        return json.dumps(value, sort_keys=True, indent=2, allow_nan=False) + "\n"
    return _dump_rows(value, 0) + "\n"


def _dump_rows(value: Any, level: int) -> str:
    pad, inner = "  " * level, "  " * (level + 1)
    if isinstance(value, dict) and value:
        items = (
            f"{inner}{json.dumps(k)}: {_dump_rows(value[k], level + 1)}" for k in sorted(value)
        )
        return "{\n" + ",\n".join(items) + f"\n{pad}}}"
    if isinstance(value, list) and any(isinstance(v, (dict, list)) for v in value):
        return "[\n" + ",\n".join(f"{inner}{_dump_rows(v, level + 1)}" for v in value) + f"\n{pad}]"
    return json.dumps(value, allow_nan=False)
