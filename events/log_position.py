"""Checking a position of a log (a :class:`~.log_files.LogPosition`: the durable high-water mark,
or where a snapshot was taken) against the file: the record ending at its byte offset must be the
one it names, by seq, stored checksum, time and stream. Only then may a reader resume there
without reading the prefix (:func:`~.log_read.read_log_after`, a snapshot's restore) or a
writer's fast open trust the prefix to its seals. Reads only the bytes just before the offset.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from .errors import CorruptLogError
from .log_files import LOG_FILE, LogMeta, LogPosition
from .scan import QUARANTINED_TYPE

__all__ = ["check_position"]


def check_position(directory: Path, meta: LogMeta, at: LogPosition) -> None:
    """Raise :class:`CorruptLogError` unless the record ending at ``at.offset`` is the one ``at``
    names (its seq, stored checksum and time): then everything up to it can be resumed from."""
    path = directory / LOG_FILE
    if at.seq == 0:
        return
    problem = None
    try:
        with path.open("rb") as f:
            size = f.seek(0, os.SEEK_END)
            start = max(0, at.offset - (1 << 20))
            f.seek(start)
            window = f.read(at.offset - start)
    except FileNotFoundError:
        size, window = 0, b""
    if size < at.offset:
        problem = f"the file ends at byte {size}, before the record of seq {at.seq}"
    elif not window.endswith(b"\n"):
        problem = f"no record ends at byte {at.offset}"
    else:
        line = window[window.rfind(b"\n", 0, len(window) - 1) + 1 : -1]
        body, _, crc = line.rpartition(b"\t")
        try:
            doc = json.loads(body)
            chain = crc
            if isinstance(doc, dict) and doc.get("type") == QUARANTINED_TYPE:
                payload = doc.get("payload")
                if isinstance(payload, dict) and isinstance(payload.get("chain"), str):
                    chain = payload["chain"].encode()
            same = (
                isinstance(doc, dict)
                and chain == b"%08x" % at.checksum
                and doc.get("seq") == at.seq
                and doc.get("time_ns") == at.time_ns
                and doc.get("stream") == meta.stream
            )
        except ValueError:
            same = False
        if not same:
            problem = f"the record ending at byte {at.offset} is not seq {at.seq} as recorded"
    if problem is not None:
        raise CorruptLogError(
            f"corrupt event log {path}: line {at.line} (byte offset {at.offset}): {problem}; "
            "the log was not changed (`objsearch log repair` keeps what it removes)",
            path=str(path),
            line=at.line,
            offset=at.offset,
        )
