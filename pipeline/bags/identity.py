"""A bag's identity: the sha256 of its storage files and their size (:func:`bag_identity`)."""

from __future__ import annotations

import hashlib
from pathlib import Path

from objsearch.pipeline.bags.formats import storage_files


def bag_identity(path: Path) -> tuple[str, int]:
    """sha256 over the bag's storage files (names and bytes) and their total size."""
    h = hashlib.sha256()
    size = 0
    for f in storage_files(path):
        h.update(f.name.encode() + b"\0")
        with f.open("rb") as fh:
            while block := fh.read(1 << 20):
                h.update(block)
                size += len(block)
    return h.hexdigest(), size
