"""Damage a log's records while keeping its checksum chain intact, for tests of what a reader says
about a bad record (not of a torn or broken chain)."""

from __future__ import annotations

import json
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from objsearch.events.log_files import read_meta


def rechain(directory: Path, edits: dict[int, Callable[[dict[str, Any]], None]]) -> None:
    """Apply ``edits`` (line number from 1 → a change to its JSON) to ``directory``'s log and chain
    every checksum again: the damage is in what was written, the chain intact."""
    chain = read_meta(directory).genesis
    out = []
    for number, line in enumerate((directory / "events.log").read_bytes().splitlines(), 1):
        body = line.rpartition(b"\t")[0]
        if number in edits:
            record = json.loads(body)
            edits[number](record)
            body = json.dumps(
                record, sort_keys=True, separators=(",", ":"), ensure_ascii=False
            ).encode()
        chain = zlib.crc32(body, chain)
        out.append(body + b"\t%08x\n" % chain)
    (directory / "events.log").write_bytes(b"".join(out))
