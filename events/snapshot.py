"""Snapshots of projections: state + seq, so a long log restarts without a full fold.

A snapshot is one JSON file per projection, ``<dir>/<name>.snapshot.json``, written atomically::

    {"format": "objsearch.snapshot/1", "projection": name, "projection_version": N,
     "stream": ..., "seq": S, "event": <id/crc32 of the event at S>, "state": {...}, "crc32": ...}

It is trusted only if everything still matches: the format, the projection's name and *code*
version (bump ``snapshot_version`` whenever ``apply`` or the state's shape changes), the stream,
the id and checksum of the event at ``seq`` in today's log (so a replaced or rewritten log is noticed), the
checksum, and — what makes it provably the fold of the log — its SHA-256, which the log's writer
recorded in ``durable.json`` when the snapshot was taken (:meth:`EventLog.attest_snapshot`). A
snapshot edited by hand and re-checksummed, one copied from another log, or one whose state does
not restore is logged once and the projection rebuilt from the log, never trusted.

A snapshot is a cache, so only a regular file is read, never past :data:`MAX_SNAPSHOT_BYTES`
(:func:`objsearch.events._fs.read_regular`: no link followed, no FIFO or device opened): anything
else at its path, or a file that cannot be read, is logged as the reason and the projection
rebuilt from the log — never a hang, an endless read or an error. Failing to write one is logged
too (the next start folds the log again).
"""

from __future__ import annotations

import hashlib
import json
import logging
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Final, Protocol, TypeVar

from . import _fs
from .envelope import Event
from .errors import EventStoreError, LogLockedError
from .log import EventLog
from .log_files import (
    LogPosition,
    position_from_json,
    position_to_json,
    read_durable_record,
    read_meta,
)
from .log_position import check_position
from .log_read import read_log, read_log_after
from .projection import fold
from .record import encode_record
from .store import Store

SNAPSHOT_FORMAT: Final = "objsearch.snapshot/1"
#: A snapshot file larger than this is not read (the log is folded instead): a cache is never
#: worth more memory than the fold it saves (the scene graph's snapshot of the 812-event test log
#: is 3.6 KB).
MAX_SNAPSHOT_BYTES: Final = 256 << 20
_log = logging.getLogger(__name__)


class Snapshottable(Protocol):
    """A projection that can be saved and restored."""

    snapshot_name: ClassVar[str]
    snapshot_version: ClassVar[int]  # bump when apply() or the state's shape changes

    @property
    def last_seq(self) -> int: ...

    @property
    def state(self) -> Any: ...

    def apply(self, event: Event) -> None: ...

    def to_snapshot(self) -> dict[str, Any]:
        """The state as plain JSON."""
        ...


P = TypeVar("P", bound=Snapshottable)


@dataclass(frozen=True, slots=True)
class Restored:
    """What :func:`restore` did: from which seq it folded, and why a snapshot was not used."""

    from_snapshot_seq: int  # 0 if rebuilt from the start
    folded: int  # events applied after the snapshot
    rejected: str | None  # why an existing snapshot was not trusted


def snapshot_path(directory: Path, name: str) -> Path:
    return directory / f"{name}.snapshot.json"


def save_snapshot(
    directory: Path | str,
    projection: Snapshottable,
    *,
    log: EventLog | Path | str,
    store: Store,
) -> Path:
    """Write ``projection``'s snapshot (at its ``last_seq``, > 0) of ``log`` and have the log's
    writer attest it.

    ``log`` is the open writer (the agent, at shutdown: the attestation is written when it
    closes), or the folder of a log no one is writing (a writer is opened for the attestation;
    :class:`LogLockedError` if another holds it). When the projection is at the writer's end,
    the snapshot records that position, whose chain checksum covers every record before it, and
    a restore resumes reading at that byte instead of from the start. ``store`` (for a folder;
    an open writer has its own) knows the log's event types.
    """
    if isinstance(log, EventLog):
        return _save(Path(directory), projection, log)
    # Sealed: the caller usually just folded this log, so its records need no second parse.
    with EventLog.open(
        log, read_meta(Path(log)).stream, create=False, verify="sealed", store=store
    ) as writer:
        return _save(Path(directory), projection, writer)


def _save(directory: Path, projection: Snapshottable, writer: EventLog) -> Path:
    seq = projection.last_seq
    if not 0 < seq <= writer.last_seq:
        raise ValueError(f"projection is at seq {seq}, outside 1..{writer.last_seq} of the log")
    log_dir = writer.directory
    position = writer.position if seq == writer.last_seq else None
    at = None
    if position is None:
        at = next(
            iter(read_log(log_dir, from_seq=seq, to_seq=seq, upcast=False, store=writer.store)),
            None,
        )
        if at is None:
            raise ValueError(f"projection is at seq {seq}, beyond the end of {log_dir}")
    body = {
        "format": SNAPSHOT_FORMAT,
        "projection": projection.snapshot_name,
        "projection_version": projection.snapshot_version,
        "stream": _stream(log_dir),
        "seq": seq,
        "event": _fingerprint(at) if at else None,
        "position": None if position is None else position_to_json(position),
        "state": projection.to_snapshot(),
    }
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    doc = text[:-1] + f',"crc32":"{zlib.crc32(text.encode()):08x}"}}'
    data = doc.encode() + b"\n"
    # Attested first: a writer that refuses (a damaged log, a failed fsync) leaves no file behind.
    writer.attest_snapshot(seq, hashlib.sha256(data).hexdigest())
    _fs.make_dirs(directory)
    path = snapshot_path(directory, projection.snapshot_name)
    _fs.write_atomic(path, data)
    return path


def restore(
    log_dir: Path | str,
    factory: Callable[[], P],
    from_snapshot: Callable[[dict[str, Any], int], P],
    *,
    snapshot_dir: Path | str,
    save: bool = True,
    store: Store,
) -> tuple[P, Restored]:
    """The projection of the whole log: from a trusted snapshot plus the events after it, else
    rebuilt by a full fold (the log read with ``store``). With ``save``, a fresh snapshot is
    written at the end."""
    fresh = factory()
    path = snapshot_path(Path(snapshot_dir), fresh.snapshot_name)
    rejected = None
    projection = fresh
    start = 0
    position = None
    whole = None
    try:
        whole = _read(path)
        if whole is not None:
            state, seq, position = _load(whole, fresh, log_dir, store)
            try:
                projection = from_snapshot(state, seq)
            except Exception as exc:  # boundary: any shape of state: rebuilt, never a traceback
                raise _Untrusted(
                    f"its state does not restore ({type(exc).__name__}: {exc})"
                ) from None
            start = seq
    except _Untrusted as exc:
        rejected = str(exc)
        position = None
        _log.warning("snapshot %s not used, rebuilding from the log: %s", path, rejected)
    before = projection.last_seq
    if position is not None:
        fold(read_log_after(log_dir, position, store=store), projection)
    else:
        fold(read_log(log_dir, from_seq=start + 1, store=store), projection)
    changed = projection.last_seq != start or rejected is not None or whole is None
    if save and changed and projection.last_seq:
        try:
            save_snapshot(snapshot_dir, projection, log=log_dir, store=store)
        except LogLockedError:
            _log.info("snapshot %s not saved: the log's writer is running", path)
        except OSError as exc:  # a cache: the next restore folds the log again
            _log.warning("snapshot %s not saved (%s); the next restore folds the log", path, exc)
    return projection, Restored(start, projection.last_seq - before, rejected)


class _Untrusted(Exception):
    pass


def _read(path: Path) -> bytes | None:
    """The snapshot file's bytes, None if there is none; :class:`_Untrusted` if something else
    is at its path (a link, a FIFO, a device, a folder), it is past
    :data:`MAX_SNAPSHOT_BYTES`, or it cannot be read."""
    try:
        return _fs.read_regular(path, MAX_SNAPSHOT_BYTES)
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise _Untrusted(f"it cannot be read: {exc.strerror or exc}") from None


def _load(
    whole: bytes, fresh: Snapshottable, log_dir: Path | str, store: Store
) -> tuple[dict[str, Any], int, LogPosition | None]:
    raw = whole.rstrip(b"\n")
    text, sep, crc = raw.rpartition(b',"crc32":"')
    if not sep or crc != b"%08x" % zlib.crc32(text + b"}") + b'"}':
        raise _Untrusted("checksum mismatch (damaged file)")
    try:
        doc = json.loads(text + b"}")
    except ValueError as exc:
        raise _Untrusted(f"not JSON: {exc}") from None
    if doc.get("format") != SNAPSHOT_FORMAT:
        raise _Untrusted(f"unknown format {doc.get('format')!r}")
    if doc.get("projection") != fresh.snapshot_name:
        raise _Untrusted(f"it is a snapshot of {doc.get('projection')!r}")
    if doc.get("projection_version") != fresh.snapshot_version:
        raise _Untrusted(
            f"projection version {doc.get('projection_version')} ≠ the code's "
            f"{fresh.snapshot_version}"
        )
    if doc.get("stream") != _stream(log_dir):
        raise _Untrusted(f"stream {doc.get('stream')!r} is not the log's")
    seq = doc.get("seq")
    if not isinstance(seq, int) or seq < 0:
        raise _Untrusted(f"bad seq {seq!r}")
    try:
        record = read_durable_record(Path(log_dir))
    except EventStoreError as exc:
        raise _Untrusted(f"the log's {exc}") from None
    if record is None or (seq, hashlib.sha256(whole).hexdigest()) not in record.attested:
        raise _Untrusted(
            "its digest is not one the log's writer attested (durable.json): edited since it "
            "was taken, taken of another log, or of a log since repaired"
        )
    if doc.get("position") is not None:
        try:
            position = position_from_json(doc["position"])
            if position.seq != seq:
                raise ValueError(f"position at seq {position.seq}, snapshot at {seq}")
            check_position(Path(log_dir), read_meta(Path(log_dir)), position)
        except (ValueError, KeyError, TypeError, EventStoreError) as exc:
            raise _Untrusted(
                f"the log at the snapshot's position is not what it saw: {exc}"
            ) from None
        return doc["state"], seq, position
    if seq:
        at = next(
            iter(read_log(log_dir, from_seq=seq, to_seq=seq, upcast=False, store=store)), None
        )
        if at is None or _fingerprint(at) != doc.get("event"):
            raise _Untrusted(f"the log's event at seq {seq} is not the one the snapshot saw")
    return doc["state"], seq, None


def _fingerprint(event: Event) -> str:
    # Ids alone are not enough: default ids depend only on (stream, seq), so a log rewritten
    # from scratch reuses them. The record's checksum covers the whole event.
    return f"{event.event_id}/{zlib.crc32(encode_record(event)):08x}"


def _stream(log_dir: Path | str) -> str:
    from .log_files import _read_meta

    return _read_meta(Path(log_dir))
