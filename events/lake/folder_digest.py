"""Digests of a lake run's files and of its manifest: how a reader knows the bytes are the ones
the commit wrote.

DuckDB does not check Parquet page checksums (a flipped bit in a data page changes the answer
without an error), and even a checking reader cannot see a flip in the footer's statistics, which
makes it skip row groups it should read. So each run's manifest records the size and SHA-256 of
every file the commit wrote, and a copy of the manifest's own SHA-256. That was the
per-run-folder lake's (``objsearch.lake/1``); this version reads such a lake only to migrate it,
and :mod:`objsearch.events.lake.folder_v1` compares the digests before a run is copied.
SHA-256 runs at ≈ 1.7 GB/s a core here (≈ 1 GB/s for BLAKE2b), and files are hashed on a few
threads (hashlib releases the GIL).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from ..sql_limits import DEFAULT_THREADS

ALGORITHM: Final = "sha256"
#: Manifest key of the files' digests: run-relative POSIX path → {"bytes": n, "digest": "sha256:…"}.
FILES_KEY: Final = "files"
#: Manifest key of the digest of the manifest itself (computed without this key).
SELF_KEY: Final = "manifest_digest"
#: The same cap as the query's DuckDB threads.
_THREADS: Final = DEFAULT_THREADS
#: Below this many bytes starting threads costs more than it saves (measured: ≈ 40 ms of pool
#: start-up on a busy machine against < 1 ms of hashing for a small run).
_THREADED_BYTES: Final = 16 << 20


@dataclass(frozen=True, slots=True)
class FileDigest:
    """What a committed file must be: its size in bytes and the digest of those bytes."""

    size: int
    digest: str

    def as_json(self) -> dict[str, Any]:
        return {"bytes": self.size, "digest": self.digest}


def bytes_digest(data: bytes | memoryview) -> FileDigest:
    return FileDigest(len(data), f"{ALGORITHM}:" + hashlib.new(ALGORITHM, data).hexdigest())


def file_digest(path: Path) -> FileDigest:
    """The digest of the file at ``path`` as it is now (raises OSError)."""
    with path.open("rb") as fh:
        h = hashlib.file_digest(fh, ALGORITHM)
        size = fh.tell()
    return FileDigest(size, f"{ALGORITHM}:{h.hexdigest()}")


def file_digests(
    paths: Iterable[Path], progress: Callable[[list[Path]], Iterable[Path]] | None = None
) -> dict[Path, FileDigest | OSError]:
    """:func:`file_digest` of many files on a few threads; an unreadable file maps to its error.
    ``progress`` wraps the paths as their digests come in (the CLI's progress line)."""

    def one(path: Path) -> FileDigest | OSError:
        try:
            return file_digest(path)
        except OSError as exc:
            return exc

    paths = list(paths)
    watched = progress or list
    if len(paths) < 2 or _total_size(paths) < _THREADED_BYTES:
        return {p: one(p) for p in watched(paths)}
    with ThreadPoolExecutor(max_workers=_THREADS) as pool:
        hashing = {p: pool.submit(one, p) for p in paths}
        return {p: hashing[p].result() for p in watched(paths)}


def _total_size(paths: list[Path]) -> int:
    total = 0
    for path in paths:
        with suppress(OSError):
            total += path.stat().st_size
    return total


def manifest_digest(doc: Mapping[str, Any]) -> str:
    """The digest of a manifest's content (every key but :data:`SELF_KEY`), canonical JSON."""
    body = {k: v for k, v in doc.items() if k != SELF_KEY}
    text = json.dumps(body, sort_keys=True, ensure_ascii=False, separators=(",", ":"))
    return f"{ALGORITHM}:" + hashlib.new(ALGORITHM, text.encode()).hexdigest()


def parse_files(value: object) -> dict[str, FileDigest]:
    """The ``files`` entry of a manifest (raises TypeError, ValueError or KeyError if malformed)."""
    if not isinstance(value, dict):
        raise TypeError(f"{FILES_KEY!r} is not an object")
    files = {}
    for name, entry in value.items():
        size, digest = entry["bytes"], entry["digest"]
        if not (isinstance(size, int) and size >= 0 and isinstance(digest, str)):
            raise ValueError(f"{FILES_KEY!r} entry {name!r}")
        files[str(name)] = FileDigest(size, digest)
    return files


def mismatch(name: str, want: FileDigest, got: FileDigest | OSError | None) -> str | None:
    """Why file ``name`` is not what its manifest records (``got``: its size alone when None,
    which only :func:`os.stat` was asked for), or None."""
    if isinstance(got, FileNotFoundError):
        return f"{name} is missing"
    if isinstance(got, OSError):
        return f"{name}: {got.strerror or got}"
    if got is None:
        return None
    if got.size != want.size:
        return f"{name} has {got.size} bytes; the manifest recorded {want.size} (cut or grown)"
    if got.digest != want.digest:
        return (
            f"{name} fails its digest: its bytes are not the ones committed (bit rot, or the file "
            "was changed or swapped after the commit)"
        )
    return None
