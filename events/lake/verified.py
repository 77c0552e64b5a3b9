"""Which content-addressed data files of a fleet lake this machine has hashed, kept outside the
lake, so a query hashes a file once per change of it, not once per query.

A data file the fleet lake writes is named after the SHA-256 of its bytes
(``type=<kind>/part-<token>-<sha256>.zstd.parquet``, :mod:`.storage`). Hashing every file
before every query would read every byte of the lake, a cost that grows with the runs; so a
reader hashes a file when it first sees it and remembers, per file, the ``stat`` identity it
had then — size, ``st_mtime_ns``, ``st_ctime_ns``, ``st_ino`` — and the hash it found. Any
rewrite through the file system changes the ctime (a process cannot set it), so a file whose
identity is the remembered one is the file that was hashed; any other is hashed again.

The cache is one JSON file per lake under :func:`cache_dir` (never in the lake: nothing a
query does writes there), replaced atomically. A cache that cannot be read, is not this
format, or names another lake counts as empty (every file is hashed again); one that cannot be
written is not written (the next query hashes again). Neither is an error.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from collections.abc import Iterable
from contextlib import suppress
from pathlib import Path
from typing import Final, NamedTuple

CACHE_ENV: Final = "OBJSEARCH_CACHE"
CACHE_FORMAT: Final = "objsearch.verified/1"
#: A hash is trusted only for a file whose ctime was this much older than the moment it was
#: hashed: a rewrite in the same tick of a coarse file-system clock as the write before it can
#: keep the ctime (Linux: one jiffy, ≤ 10 ms; FAT, some network file systems: 1-2 s). A younger
#: file is hashed again by the next reader, until it is old enough.
RACY_NS: int = 2_000_000_000
#: Bytes read at a time while hashing.
HASH_CHUNK: Final = 1 << 20
_log = logging.getLogger(__name__)


def cache_dir() -> Path:
    """``$OBJSEARCH_CACHE``, else ``$XDG_CACHE_HOME/objsearch``, else ``~/.cache/objsearch``."""
    env = os.environ.get(CACHE_ENV)
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "objsearch"


class Identity(NamedTuple):
    """What ``stat`` says of a file: any rewrite changes at least the ctime."""

    size: int
    mtime_ns: int
    ctime_ns: int
    ino: int

    @classmethod
    def of(cls, st: os.stat_result) -> Identity:
        return cls(st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino)


class _Entry(NamedTuple):
    identity: Identity
    sha256: str
    hashed_at_ns: int


def sha256_file(path: Path) -> str:
    """The SHA-256 of a file's bytes (hex), read :data:`HASH_CHUNK` at a time."""
    digest = hashlib.sha256()
    with path.open("rb", buffering=0) as fh:
        while chunk := fh.read(HASH_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


class VerifiedFiles:
    """The verification cache of one lake (``uri``: the table's absolute location)."""

    def __init__(self, uri: str, directory: Path | None = None) -> None:
        self.uri = uri
        name = hashlib.sha256(uri.encode()).hexdigest()[:32]
        self.path = (directory or cache_dir()) / "fleet-verified" / f"{name}.json"
        self._entries = self._load()
        self._changed = False

    def _load(self) -> dict[str, _Entry]:
        try:
            doc = json.loads(self.path.read_text(encoding="utf-8"))
        except (OSError, ValueError, UnicodeDecodeError):
            return {}  # none yet, unreadable or garbled: every file is hashed again
        if not isinstance(doc, dict) or doc.get("format") != CACHE_FORMAT:
            return {}
        if doc.get("lake") != self.uri or not isinstance(doc.get("files"), dict):
            return {}
        entries = {}
        for rel, value in doc["files"].items():
            if (
                isinstance(value, list)
                and len(value) == 6
                and all(type(v) is int for v in value[:4])
                and isinstance(value[4], str)
                and type(value[5]) is int
            ):
                entries[str(rel)] = _Entry(Identity(*value[:4]), value[4], value[5])
        return entries

    def known(self, rel: str, identity: Identity, sha256: str) -> bool:
        """Whether ``rel`` was hashed to ``sha256`` when it had ``identity``, long enough
        after its last change (:data:`RACY_NS`) that a rewrite since would show."""
        entry = self._entries.get(rel)
        return (
            entry is not None
            and entry.identity == identity
            and entry.sha256 == sha256
            and identity.ctime_ns + RACY_NS <= entry.hashed_at_ns
        )

    def remember(self, rel: str, identity: Identity, sha256: str, hashed_at_ns: int) -> None:
        entry = _Entry(identity, sha256, hashed_at_ns)
        if self._entries.get(rel) != entry:
            self._entries[rel] = entry
            self._changed = True

    def keep_only(self, rels: Iterable[str]) -> None:
        """Forget files no longer in the table (the cache stays as small as the table)."""
        wanted = set(rels)
        gone = [rel for rel in self._entries if rel not in wanted]
        for rel in gone:
            del self._entries[rel]
        self._changed = self._changed or bool(gone)

    def save(self) -> None:
        """Write the cache if it changed: a temporary file of this process beside it, then a
        rename (readers see the old cache or the new one). Not fsync'ed: a cache lost in a
        crash costs a hash of each file, nothing else. A cache folder that cannot be written
        leaves the cache unwritten (logged at debug level)."""
        if not self._changed:
            return
        doc = {
            "format": CACHE_FORMAT,
            "lake": self.uri,
            "files": {
                rel: [*e.identity, e.sha256, e.hashed_at_ns] for rel, e in self._entries.items()
            },
        }
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_text(json.dumps(doc, separators=(",", ":")), encoding="utf-8")
            os.replace(tmp, self.path)
        except OSError as exc:
            _log.debug("verification cache %s not written: %s", self.path, exc)
            with suppress(OSError):
                tmp.unlink(missing_ok=True)
            return
        self._changed = False
