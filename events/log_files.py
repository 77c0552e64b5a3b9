"""What a log directory holds besides its records, and the small files that say it.

``meta.json`` (format, stream, run id: :class:`LogMeta`), ``durable.json`` (the high-water
mark, the seals and the snapshots' attestations: :class:`DurableRecord`) and the names of the
directory's files. The log's layout is described in :mod:`.log`.
"""

from __future__ import annotations

import json
import uuid
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from . import _fs
from .errors import (
    CorruptLogError,
    EventStoreError,
    LogNotFoundError,
)
from .seal import Seal, seals_from_json, seals_to_json

LOG_FORMAT: Final = "objsearch.events/2"
#: Read and appended to as they are: plain CRC-32 per record, ids from the stream name.
LOG_FORMAT_V1: Final = "objsearch.events/1"
LOG_FILE: Final = "events.log"
META_FILE: Final = "meta.json"
DURABLE_FILE: Final = "durable.json"
LOCK_FILE: Final = "LOCK"
#: Prefix of the files that keep bytes a writer or ``repair_log`` took out of ``events.log``.
QUARANTINE_PREFIX: Final = "events.log."


@dataclass(frozen=True, slots=True)
class LogMeta:
    """What ``meta.json`` says: the on-disk format, the stream and (format 2) the run id."""

    format: str
    stream: str
    run_id: str | None

    @property
    def chained(self) -> bool:
        return self.format == LOG_FORMAT

    @property
    def genesis(self) -> int:
        """The checksum the first record's chains from (0: plain CRC-32 in format 1)."""
        if not self.chained:
            return 0
        return zlib.crc32(f"{self.format}\n{self.stream}\n{self.run_id}\n".encode())

    def id_key(self) -> str:
        """What default event ids are derived from: the run id (format 1: the stream)."""
        return self.run_id if self.run_id is not None else self.stream


@dataclass(frozen=True, slots=True)
class LogPosition:
    """A point in a log: right after the record of ``seq``, which ends at byte ``offset`` on line
    ``line`` with chain checksum ``checksum`` and ``time_ns``. The durable high-water mark is one;
    so is where a snapshot was taken. A reader can resume there after checking that the record
    ending at ``offset`` is still that record (:func:`read_log_after`)."""

    seq: int
    offset: int
    checksum: int
    line: int
    time_ns: int


#: The durable high-water mark: where the log ended when its writer last closed.
Durable = LogPosition

#: How many snapshot attestations ``durable.json`` keeps (the newest).
MAX_ATTESTED: Final = 8


@dataclass(frozen=True, slots=True)
class DurableRecord:
    """All of ``durable.json``: the high-water mark, the seals of every byte before it (None in a
    mark written before seals existed) and the snapshots the writer attested: (seq, SHA-256 of
    the snapshot file) — a snapshot is trusted only if its digest is here."""

    position: LogPosition
    seals: tuple[Seal, ...] | None
    attested: tuple[tuple[int, str], ...] = ()


@dataclass(frozen=True, slots=True)
class TornTail:
    """An unterminated fragment after the last newline: an append that never completed."""

    path: Path
    offset: int  # where the last good record ends: the file is cut (or read) up to here
    length: int  # bytes from ``offset`` to the end of the file
    line: int  # line number (1-based) of the fragment
    quarantine: Path | None = None  # where a writer kept the bytes it cut
    lines: int = 1
    complete: bool = False
    reason: str = "last line has no newline (interrupted append)"


def read_meta(directory: Path) -> LogMeta:
    """What ``meta.json`` says, after checking the directory is a log this code can read."""
    meta_path = directory / META_FILE
    try:
        raw = meta_path.read_bytes()
    except (FileNotFoundError, NotADirectoryError):
        if not directory.is_dir():
            raise LogNotFoundError(
                f"no event log at {directory}: the directory does not exist"
            ) from None
        extra = f" (but {LOG_FILE} exists)" if (directory / LOG_FILE).exists() else ""
        raise LogNotFoundError(
            f"no event log at {directory}: {META_FILE} is missing{extra}"
        ) from None
    try:
        meta = json.loads(raw)
    except ValueError as exc:
        raise EventStoreError(f"{meta_path} is not valid JSON: {exc}") from exc
    found = meta.get("format") if isinstance(meta, dict) else None
    if found not in (LOG_FORMAT, LOG_FORMAT_V1):
        raise EventStoreError(
            f"{meta_path}: unsupported log format {found!r} (this code reads {LOG_FORMAT!r} "
            f"and {LOG_FORMAT_V1!r})"
        )
    assert isinstance(meta, dict)
    expected = {"format", "stream"} | ({"run_id"} if found == LOG_FORMAT else set())
    if set(meta) != expected:
        raise EventStoreError(f"{meta_path}: expected exactly the keys {sorted(expected)}")
    stream = meta["stream"]
    if not (isinstance(stream, str) and stream):
        raise EventStoreError(f"{meta_path}: 'stream' is missing or not a non-empty string")
    run_id = meta.get("run_id")
    if found == LOG_FORMAT:
        try:
            valid = isinstance(run_id, str) and str(uuid.UUID(run_id)) == run_id
        except ValueError:
            valid = False
        if not valid:
            raise EventStoreError(f"{meta_path}: 'run_id' is not a canonical UUID: {run_id!r}")
    return LogMeta(found, stream, run_id)


def _read_meta(directory: Path) -> str:
    """The stream named in ``meta.json`` (see :func:`read_meta`)."""
    return read_meta(directory).stream


def read_durable(directory: Path) -> Durable | None:
    """The high-water mark the writer left at its last close, or None if it left none."""
    record = read_durable_record(directory)
    return None if record is None else record.position


def read_durable_record(directory: Path) -> DurableRecord | None:
    """All of ``durable.json`` (:class:`DurableRecord`), or None if there is none."""
    path = directory / DURABLE_FILE
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        return None
    try:
        doc = json.loads(raw)
        if not isinstance(doc, dict):
            raise ValueError("not a JSON object")
        extra = {k: doc.pop(k) for k in ("seals", "snapshots") if k in doc}
        position = position_from_json(doc)
        seals = seals_from_json(extra["seals"]) if "seals" in extra else None
        if seals and seals[-1].end != position.offset:
            raise ValueError(f"seals end at byte {seals[-1].end}, the mark at {position.offset}")
        attested = _attested_from_json(extra.get("snapshots", []))
        mark = DurableRecord(position, seals, attested)
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise CorruptLogError(
            f"corrupt event log {directory}: {path} is damaged ({exc}); the log was not changed "
            "(`objsearch log repair` rewrites it from the records)",
            path=str(path),
            line=0,
            offset=0,
        ) from exc
    return mark


def _attested_from_json(doc: Any) -> tuple[tuple[int, str], ...]:
    if not isinstance(doc, list):
        raise ValueError("snapshots: not a list")
    out = []
    for item in doc:
        if not (
            isinstance(item, list)
            and len(item) == 2
            and type(item[0]) is int
            and isinstance(item[1], str)
        ):
            raise ValueError("snapshots: an item is not [seq, sha256]")
        out.append((item[0], item[1]))
    return tuple(out)


def write_durable(
    directory: Path,
    mark: Durable,
    seals: tuple[Seal, ...] = (),
    attested: tuple[tuple[int, str], ...] = (),
) -> None:
    """Write ``durable.json`` atomically: the mark, the seals of ``[0, mark.offset)`` and the
    attested snapshots."""
    if seals and seals[-1].end != mark.offset:
        raise ValueError(f"seals end at byte {seals[-1].end}, the mark at {mark.offset}")
    doc: dict[str, Any] = position_to_json(mark)
    doc["seals"] = seals_to_json(seals)
    doc["snapshots"] = [list(a) for a in attested]
    _fs.write_atomic(directory / DURABLE_FILE, json.dumps(doc, sort_keys=True).encode() + b"\n")


def position_to_json(at: LogPosition) -> dict[str, Any]:
    return {
        "seq": at.seq,
        "offset": at.offset,
        "checksum": f"{at.checksum:08x}",
        "line": at.line,
        "time_ns": at.time_ns,
    }


def position_from_json(doc: Any) -> LogPosition:
    """The inverse of :func:`position_to_json`; ``ValueError`` if ``doc`` is not one."""
    if not isinstance(doc, dict) or set(doc) != {"seq", "offset", "checksum", "line", "time_ns"}:
        raise ValueError("unexpected keys")
    at = LogPosition(
        seq=doc["seq"],
        offset=doc["offset"],
        checksum=int(doc["checksum"], 16),
        line=doc["line"],
        time_ns=doc["time_ns"],
    )
    if not all(type(v) is int and v >= 0 for v in (at.seq, at.offset, at.line, at.time_ns)):
        raise ValueError("unexpected values")
    return at
