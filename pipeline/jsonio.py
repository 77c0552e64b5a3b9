"""Canonical JSON and atomic writes: a rebuild must be byte-identical and never half-written."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
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


def dumps(value: Any) -> str:
    """Sorted keys, 2-space indent, rounded floats, trailing newline."""
    return json.dumps(canonical(value), sort_keys=True, indent=2, allow_nan=False) + "\n"


def write_atomic(path: Path, content: bytes) -> None:
    """Write ``content`` to ``path`` via a temporary file in the same folder and a rename.

    A crash or an error leaves either the old file or the new one, never a truncated file.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    # os.open with 0o666 lets the umask decide permissions, as a plain open() would.
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(content)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
