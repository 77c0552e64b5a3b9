"""The head record: the latest version a commit of this lake made (:data:`HEAD_FILE`, in the
table's folder), so a table whose newest commit files were deleted is told from one that never
had them (:meth:`~objsearch.events.lake.checks.LakeChecks.check_runs`)."""

from __future__ import annotations

import hashlib
import json
import logging
import os
import uuid
from pathlib import Path
from typing import TYPE_CHECKING, Final

from .storage import _filesystem

if TYPE_CHECKING:
    from .table import LakeBase

_log = logging.getLogger(__name__)

#: Where a commit records the latest version it made (in the table's folder; Delta readers and
#: vacuum leave a name starting with ``_`` alone): a version of the table older than this means
#: its newest commit files were deleted (:meth:`~objsearch.events.lake.checks.LakeChecks.check_runs`).
HEAD_FILE: Final = "_objsearch_head.json"
HEAD_FORMAT: Final = "objsearch.head/1"


def _head_check(version: int) -> str:
    return hashlib.sha256(f"{HEAD_FORMAT}:{version}".encode()).hexdigest()[:16]


def recorded_head(lake: LakeBase) -> int | None:
    """The latest version a commit of ``lake`` recorded making (:data:`HEAD_FILE`), or
    None (no such record, or one that does not check: then nothing is compared)."""
    try:
        if lake.remote:
            fs, base = _filesystem(lake.uri)
            with fs.open_input_file(f"{base}/{HEAD_FILE}") as fh:
                text = fh.read(4096).decode()
        else:
            text = (Path(lake.uri) / HEAD_FILE).read_text(encoding="utf-8")
        doc = json.loads(text)
        version = doc["version"]
        if type(version) is int and doc.get("check") == _head_check(version):
            return version
    except FileNotFoundError:
        return None
    except (OSError, ValueError, TypeError, KeyError, UnicodeDecodeError):
        pass
    _log.warning(
        "%s: %s does not check; ignored (a deleted newest commit file would go unseen until "
        "the next commit rewrites it)",
        lake.root,
        HEAD_FILE,
    )
    return None


def record_head(lake: LakeBase, version: int) -> None:
    """Record that ``lake``'s table reached ``version`` (after a commit; :data:`HEAD_FILE`),
    replaced atomically. Not a durable step: a record lost in a crash, or lowered by a
    slower writer, is older than the log, which costs only the check of newer commits."""
    text = json.dumps({"format": HEAD_FORMAT, "version": version, "check": _head_check(version)})
    try:
        if lake.remote:
            fs, base = _filesystem(lake.uri)
            with fs.open_output_stream(f"{base}/{HEAD_FILE}") as out:
                out.write(text.encode())
            return
        tmp = Path(lake.uri) / f".{HEAD_FILE}.{os.getpid()}.{uuid.uuid4().hex}.tmp"
        try:
            tmp.write_text(text, encoding="utf-8")
            os.replace(tmp, Path(lake.uri) / HEAD_FILE)
        finally:
            tmp.unlink(missing_ok=True)
    except OSError as exc:
        _log.warning("%s: %s not written (%s); the commit stands", lake.root, HEAD_FILE, exc)
