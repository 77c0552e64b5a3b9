"""The append-only event log: one stream per directory.

Layout of a log directory::

    meta.json     {"format": "objsearch.events/2", "stream": ..., "run_id": <uuid>}, written once
    events.log    one record per line (see record.py); only ever appended to; flock'ed by the writer
    durable.json  the durable high-water mark: seq, byte offset and checksum of the last record when
                  the writer last closed (so a log cut at a record boundary is noticed)
    LOCK          holds the writer's pid (a hint for error messages); also flock'ed

``meta.json`` exists because the records alone can't say which stream an empty log belongs to or
which on-disk format a directory uses; a reader refuses a format it doesn't know instead of
reporting every line as corrupt. Its run id makes event ids and the checksum chain unique to this
log, so records of another log never pass as this one's.

The writer locks ``events.log`` itself: a lock file can be deleted from under a writer (and a
second writer then locks a new inode of the same name); the log cannot be, without the writer
noticing (it checks the file is still linked at every fsync).

Here: the writer (:class:`EventLog`). Reading is :mod:`.log_read`; what the directory's other
files say and how they are read and written is in :mod:`.log_files`; one checked pass over the
records, which both use, is :mod:`.scan`. The writer's open checks the prefix with
:mod:`.log_seal_check` and :mod:`.log_position` and cuts a torn tail with :mod:`.log_torn_tail`.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
import uuid
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from types import TracebackType
from typing import Any

import msgspec

from . import _fs
from .envelope import Event, _Adopted, event_ids
from .errors import (
    DuplicateEventError,
    InvalidEventError,
    LogClosedError,
    LogLockedError,
    LogNotFoundError,
    StreamMismatchError,
    WrongExpectedSeqError,
)
from .log_files import (
    LOCK_FILE,
    LOG_FILE,
    LOG_FORMAT,
    MAX_ATTESTED,
    META_FILE,
    Durable,
    LogMeta,
    LogPosition,
    TornTail,
    read_durable_record,
    read_meta,
    write_durable,
)
from .log_position import check_position
from .log_seal_check import _check_sealed, _SealCheck
from .log_torn_tail import _cut_torn_tail
from .record import Framer
from .scan import QUARANTINED_TYPE, _Cursor, _Scan
from .seal import Sealer
from .store import Encoded, Store


def _chain_redirected(event_type: str, version: int) -> InvalidEventError:
    """The error for an append of a quarantine record that redirects the checksum chain: only
    the repair writes one, in place of a damaged record."""
    return InvalidEventError(
        f"invalid {event_type} v{version} event: payload.chain: only `objsearch log "
        "repair` redirects the checksum chain (it writes the record in place of a "
        "damaged one)",
        event_type=event_type,
        version=version,
        path="payload.chain",
        reason="not null",
    )


__all__ = ["EventLog"]

#: At most this many written records wait to be added to the seals (:meth:`EventLog._seal`).
_SEAL_EVERY = 256


class EventLog:
    """The single writer of one stream's log. Use :meth:`open`; close it (or use ``with``).

    Every append is validated before a byte is written, and is on disk (written and fsync'ed)
    before it returns, except inside :meth:`batch`, which fsyncs once at its end. Not
    thread-safe: the lock makes this the stream's only writer, so give it one thread too.
    """

    def __init__(
        self,
        *,
        directory: Path,
        meta: LogMeta,
        fd: int,
        lock_fd: int,
        at: _Cursor,
        durable: Durable | None,
        torn_tail: TornTail | None,
        store: Store,
        wall_clock: Callable[[], int],
        ids: dict[str, int] | None,
        sealer: Sealer,
        attested: tuple[tuple[int, str], ...],
        seal_check: _SealCheck | None = None,
    ) -> None:
        # Private: only open() knows how to reach a consistent state (lock, meta, recovery).
        self._directory = directory
        self._meta = meta
        # What every append reads of the meta, read once (the meta never changes while open).
        self._stream = meta.stream
        self._id_key = meta.id_key()
        self._next_id = event_ids(self._id_key)  # seq → the default id (deterministic_event_id)
        self._chained = meta.chained
        self._framer = Framer(meta.stream)
        self._fd = fd
        self._lock_fd = lock_fd
        self._at = at
        self._durable = durable
        self._torn_tail = torn_tail
        self._store = store
        self._registry = store.registry
        self._wall_clock = wall_clock
        # event id → byte offset of its record: what makes appends idempotent. None after a fast
        # open (verify="sealed") until the first explicit id asks for it.
        self._ids = ids
        self._sealer = sealer
        # Records written and not yet added to the seals: added together (one CRC over them) at
        # the next fsync or every _SEAL_EVERY records, not one call per append.
        self._unsealed: list[bytes] = []
        self._sealed_in_mark = sealer.closed_count  # closed seals already in durable.json
        self._attested = attested
        self._attest_pending = False
        self._seal_check = seal_check
        self._batch_depth = 0
        self._unsynced = False
        self._closed = False
        self._broken: str | None = None

    @classmethod
    def open(
        cls,
        directory: Path | str,
        stream: str,
        *,
        create: bool = True,
        run_id: str | None = None,
        store: Store,
        wall_clock: Callable[[], int] = time.time_ns,
        verify: str = "all",
    ) -> EventLog:
        """Open ``directory`` for appending to ``stream``, creating it if allowed.

        Takes the log's lock (:class:`LogLockedError` if another writer has it), checks the
        format and stream (:class:`StreamMismatchError`), verifies every record
        (:class:`CorruptLogError`, the file untouched) and cuts an unterminated last fragment
        with a :class:`TornTailWarning`, keeping its bytes in a quarantine file beside the log.
        ``run_id`` is the id a log created by this call gets (a random UUID if None; pass one
        derived from a seed for reproducible logs); an existing log keeps its own.
        ``store`` says which event types and versions exist and encodes what is appended (the
        product's is :data:`objsearch.agent.catalogue.STORE`).
        ``wall_clock`` stamps ``recorded_at_ns``; pass a fixed one for byte-identical logs.
        ``verify="sealed"`` (an agent's fast restart) checks every byte before the durable
        high-water mark against its seals (CRC-32 of whole ranges, no parsing) and parses every
        record after it; a log without seals is verified record by record. Either way no
        acknowledged byte goes unchecked before the first append.
        """
        directory = Path(directory)
        if verify not in ("all", "sealed"):
            raise ValueError(f"verify must be 'all' or 'sealed', got {verify!r}")
        if not (isinstance(stream, str) and stream):
            raise ValueError(f"stream must be a non-empty string, got {stream!r}")
        if run_id is not None and str(_parse_uuid(run_id, "run_id")) != run_id:
            raise ValueError(f"run_id must be a canonical (lower-case) UUID, got {run_id!r}")
        if directory.exists() and not directory.is_dir():
            raise LogNotFoundError(f"no event log at {directory}: it is not a directory")
        if not directory.is_dir():
            if not create:
                raise LogNotFoundError(
                    f"no event log at {directory}: the directory does not exist (create=False)"
                )
            _fs.make_dirs(directory)
        elif not create or _non_empty(directory / LOG_FILE):
            read_meta(directory)  # before anything is created: a LogNotFoundError leaves no trace

        log_path = directory / LOG_FILE
        created = not log_path.exists()
        fd = os.open(log_path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_CLOEXEC, 0o644)
        lock_fd = -1
        try:
            if created:
                _fs.fsync_dir(directory)
            hint_fd = _fs.try_lock(directory / LOCK_FILE) if _fs.flock_nb(fd) else None
            if hint_fd is None:
                raise LogLockedError(
                    f"event log {directory} is already open for writing (its lock is held"
                    f"{_fs.lock_holder_hint(directory / LOCK_FILE)}); a stream has exactly one "
                    "writer"
                )
            lock_fd = hint_fd
            if os.fstat(fd).st_ino != os.stat(log_path).st_ino:
                raise LogLockedError(
                    f"event log {log_path} was replaced while it was being opened; try again"
                )
            return cls._open_locked(
                directory, stream, fd, lock_fd, run_id, store, wall_clock, verify
            )
        except BaseException:
            os.close(fd)
            if lock_fd >= 0:
                os.close(lock_fd)
            raise

    @classmethod
    def _open_locked(
        cls,
        directory: Path,
        stream: str,
        fd: int,
        lock_fd: int,
        run_id: str | None,
        store: Store,
        wall_clock: Callable[[], int],
        verify: str = "all",
    ) -> EventLog:
        # events.log is created (to be locked) before meta.json: a crash between the two leaves
        # an empty events.log without meta.json, which is still a log waiting to be created.
        if (directory / META_FILE).exists() or _non_empty(directory / LOG_FILE):
            meta = read_meta(directory)
            if meta.stream != stream:
                raise StreamMismatchError(
                    f"event log {directory} belongs to stream {meta.stream!r}, not {stream!r}"
                )
        else:
            meta = LogMeta(LOG_FORMAT, stream, run_id or str(uuid.uuid4()))
            doc = {"format": meta.format, "stream": meta.stream, "run_id": meta.run_id}
            data = json.dumps(doc, sort_keys=True, ensure_ascii=False).encode() + b"\n"
            _fs.write_atomic(directory / META_FILE, data)
        registry = store.registry
        record = read_durable_record(directory)
        durable = None if record is None else record.position
        log_path = directory / LOG_FILE
        ids: dict[str, int] | None = {}
        seal_check = None
        if verify == "sealed" and record is not None and record.seals:
            # Every acknowledged byte is checked before anything is appended: the sealed
            # prefix by CRC on a thread of its own (the caller restores its state meanwhile;
            # the first append, batch or close waits for it), the rest record by record here.
            check_position(directory, meta, record.position)
            seal_check = _SealCheck(directory, meta, registry, record)
            ids = None  # the prefix is not indexed: built on the first explicit event id
            sealer = Sealer.resume(record.seals)
            scan = _Scan(
                log_path, meta, registry=registry, start=durable, sealer=sealer, payloads=False
            )
            for _ in scan:
                pass
        else:
            sealer = Sealer(crc=meta.genesis)
            scan = _Scan(
                log_path,
                meta,
                registry=registry,
                durable=durable,
                ids=ids,
                sealer=sealer,
                payloads=False,
            )
            for _ in scan:
                pass
            if record is not None and record.seals:
                # The records verify; seals that do not match them mean durable.json is damaged.
                _check_sealed(directory, meta, registry, record)
        tail = scan.torn_tail
        if tail is not None:
            if seal_check is not None:
                seal_check.result()  # a damaged log is left exactly as it is
            tail = _cut_torn_tail(fd, tail)
        return cls(
            directory=directory,
            meta=meta,
            fd=fd,
            lock_fd=lock_fd,
            at=scan.at,
            durable=durable,
            torn_tail=tail,
            store=store,
            wall_clock=wall_clock,
            ids=ids,
            sealer=sealer,
            attested=() if record is None else record.attested,
            seal_check=seal_check,
        )

    @property
    def position(self) -> LogPosition:
        """Where the log ends now (after the last appended record)."""
        at = self._at
        return LogPosition(at.seq, at.offset, at.checksum, at.line, at.time_ns)

    @property
    def store(self) -> Store:
        """The store this log was opened with (its event types, versions and upcasters)."""
        return self._store

    @property
    def directory(self) -> Path:
        return self._directory

    @property
    def stream(self) -> str:
        return self._meta.stream

    @property
    def run_id(self) -> str | None:
        """The log's run id (None for a format-1 log)."""
        return self._meta.run_id

    @property
    def last_seq(self) -> int:
        """Seq of the last appended record (0 for an empty log)."""
        return self._at.seq

    @property
    def last_time_ns(self) -> int:
        """``time_ns`` of the last appended record (0 for an empty log); never goes back."""
        return self._at.time_ns

    @property
    def torn_tail(self) -> TornTail | None:
        """What :meth:`open` cut from the end of the file, if anything."""
        return self._torn_tail

    @property
    def closed(self) -> bool:
        return self._closed

    def append(
        self,
        type: str,
        payload: Mapping[str, Any],
        *,
        time_ns: int,
        task_id: str | None = None,
        version: int | None = None,
        event_id: str | None = None,
        expected_last_seq: int | None = None,
    ) -> Event:
        """Validate, write and (outside a batch) fsync one event; return it as stored.

        ``version`` defaults to the type's latest schema version, ``event_id`` to
        :func:`deterministic_event_id` of the log's run id and the seq. ``time_ns`` may not be
        earlier than the last event's. Raises :class:`InvalidEventError` with the file unchanged.

        Idempotent by event id: if the stream already holds ``event_id`` with the same type,
        version, task, time and payload, nothing is written and the stored event is returned
        (re-running an import never duplicates); the same id with other content raises
        :class:`DuplicateEventError`. With ``expected_last_seq``, the append is refused with
        :class:`WrongExpectedSeqError` unless the log ends at that seq (optimistic concurrency,
        like an expected version); the duplicate check comes first, so a retry still succeeds.
        """
        if self._closed or self._seal_check is not None or self._broken is not None:
            self._check_usable()  # raises (or waits for the seal check): not per append
        encoded = self._store.encode(type, payload, version)
        return self._append(encoded, time_ns, task_id, event_id, expected_last_seq)

    def append_record(
        self,
        record: msgspec.Struct,
        *,
        time_ns: int,
        task_id: str | None = None,
        event_id: str | None = None,
        expected_last_seq: int | None = None,
    ) -> Event:
        """:meth:`append` of a typed record of the store's catalogue (``Catalogue.records``):
        its type and version are the record's, and the same bytes are stored as for its payload
        dict (``Store.encode_record``). The event returned decodes its payload only when it is
        read."""
        if self._closed or self._seal_check is not None or self._broken is not None:
            self._check_usable()  # raises (or waits for the seal check): not per append
        encoded = self._store.encode_record(record)
        return self._append(encoded, time_ns, task_id, event_id, expected_last_seq)

    def _append(
        self,
        encoded: Encoded,
        time_ns: int,
        task_id: str | None,
        event_id: str | None,
        expected_last_seq: int | None,
    ) -> Event:
        """The one way into the log: a payload the store encoded, framed with its envelope,
        written with one ``write`` and, outside a batch, fsync'ed (the same fact already stored
        under ``event_id`` is returned instead). One function, not a call per step: it runs
        once per append, and each call between the steps was a measurable part of it."""
        event_type, version, payload_json, payload = encoded
        if event_type == QUARANTINED_TYPE and payload.get("chain") is not None:
            raise _chain_redirected(event_type, version)
        at = self._at
        made_id = event_id is None
        if made_id and expected_last_seq is None:
            seq = at.seq + 1  # :meth:`_claim`'s default case, inline
            event_id = self._next_id(seq)
            if self._ids is not None and event_id in self._ids:
                raise self._default_id_used(event_id, seq)
        else:
            seq, event_id, stored = self._claim(event_id, expected_last_seq)
            if stored:
                return self._existing(event_id, encoded, time_ns, task_id)
        recorded_at_ns = self._wall_clock()
        last_time_ns = at.time_ns
        event: Event
        if (
            # What the writer made is valid by construction: the default id (canonical), the
            # log's stream (checked at open), the next seq. What the caller or the store gave is
            # checked here by the envelope's rules (_plausible's, exact types); any doubt goes to
            # Event._appended, which checks every field and words the error.
            made_id
            and type(time_ns) is int
            and time_ns >= last_time_ns  # so >= 0: the last was
            and type(recorded_at_ns) is int
            and recorded_at_ns >= 0
            and (task_id is None or (type(task_id) is str and task_id != ""))
            and type(event_type) is str
            and event_type != ""
            and type(version) is int
            and version >= 1
        ):
            event = _Adopted(
                event_id=event_id,
                stream=self._stream,
                seq=seq,
                time_ns=time_ns,
                recorded_at_ns=recorded_at_ns,
                type=event_type,
                version=version,
                task_id=task_id,
                payload=payload,
            )
        else:
            event = Event._appended(
                payload,
                event_id=event_id,
                stream=self._stream,
                seq=seq,
                time_ns=time_ns,
                recorded_at_ns=recorded_at_ns,
                type=event_type,
                version=version,
                task_id=task_id,
            )
            if time_ns < last_time_ns:
                self._check_time(event)  # raises
        record, checksum = self._framer.frame(
            event, payload_json, at.checksum if self._chained else 0
        )
        try:
            # One record is one write (readers see it at once), all but always whole.
            written = os.write(self._fd, record)
        except BaseException as exc:
            self._undo_write(exc)
            raise
        if written != len(record):
            self._write(record[written:])  # a short write: the rest follows
        unsealed = self._unsealed
        unsealed.append(record)
        if len(unsealed) >= _SEAL_EVERY:
            self._seal()
        if self._ids is not None:
            self._ids[event_id] = at.offset
        at.offset += len(record)
        at.line += 1
        at.seq = seq
        at.checksum = checksum
        at.time_ns = event.time_ns
        if self._batch_depth:
            self._unsynced = True
        else:
            self._sync()
        return event

    def _claim(self, event_id: str | None, expected_last_seq: int | None) -> tuple[int, str, bool]:
        """The seq and id of the next record, and whether that id is already stored (the caller
        then checks the append asks for the same fact); the expected seq checked."""
        at = self._at
        seq = at.seq + 1
        ids = self._ids
        if ids is None and event_id is not None:
            ids = self._index_ids()
        if event_id is not None and ids is not None and event_id in ids:
            return seq, event_id, True
        if expected_last_seq is not None and expected_last_seq != at.seq:
            raise WrongExpectedSeqError(
                f"event log {self._directory} ends at seq {at.seq}, "
                f"not at the expected seq {expected_last_seq}; nothing was written"
            )
        if event_id is None:
            event_id = self._next_id(seq)
            # After a fast open the prefix is not indexed; a default id is new by construction
            # unless an explicit id copied it, which indexing on that explicit append catches.
            if ids is not None and event_id in ids:
                raise self._default_id_used(event_id, seq)
        return seq, event_id, False

    def _default_id_used(self, event_id: str, seq: int) -> DuplicateEventError:
        return DuplicateEventError(
            f"the default id {event_id} of seq {seq} is already used by an earlier "
            f"event in {self._directory} (an explicit id copied from this stream?)"
        )

    def _check_time(self, event: Event) -> None:
        last = self._at.time_ns
        if event.time_ns < last:
            raise InvalidEventError(
                f"invalid {event.type} v{event.version} event: time_ns {event.time_ns} is before "
                f"the last event's ({last}); a stream's time never runs backwards",
                event_type=event.type,
                version=event.version,
                path="time_ns",
                reason="earlier than the previous event",
            )

    def _index_ids(self) -> dict[str, int]:
        ids: dict[str, int] = {}
        scan = _Scan(
            self._directory / LOG_FILE, self._meta, registry=self._registry, ids=ids, payloads=False
        )
        for event in scan:
            if event.seq >= self._at.seq:
                break
        self._ids = ids
        return ids

    def _existing(
        self, event_id: str, encoded: Encoded, time_ns: int, task_id: str | None
    ) -> Event:
        """The stored event with ``event_id``, if the new append asks for the same fact."""
        assert self._ids is not None
        with (self._directory / LOG_FILE).open("rb") as f:
            f.seek(self._ids[event_id])
            line = f.readline()[:-1]
        # Its checksum was verified when the log was opened; here only its content matters.
        stored = Event._adopt(json.loads(line.rpartition(b"\t")[0]))
        wanted = Event(
            event_id=event_id,
            stream=self._meta.stream,
            seq=stored.seq,
            time_ns=time_ns,
            recorded_at_ns=stored.recorded_at_ns,
            type=encoded.type,
            version=encoded.version,
            task_id=task_id,
            payload=encoded.payload,
        )
        if wanted != stored:
            differ = [
                name
                for name in ("type", "version", "task_id", "time_ns", "payload")
                if getattr(wanted, name) != getattr(stored, name)
            ]
            raise DuplicateEventError(
                f"event id {event_id} is already in {self._directory} at seq {stored.seq} with "
                f"a different {', '.join(differ)}; an id names one fact, nothing was written"
            )
        return stored

    @contextlib.contextmanager
    def batch(self) -> Iterator[None]:
        """Group appends under one fsync, done when the outermost batch exits.

        The events are acknowledged (durable) only then. Not a transaction: if the block raises,
        the events appended so far stay in the log (readers may already have seen them) and are
        still fsync'ed.
        """
        self._check_usable()
        self._batch_depth += 1
        try:
            yield
        finally:
            self._batch_depth -= 1
            if self._batch_depth == 0 and self._unsynced and self._broken is None:
                self._sync()

    def close(self) -> None:
        """Fsync anything pending, record the high-water mark, release the lock. Idempotent."""
        if self._closed:
            return
        try:
            if self._seal_check is not None:
                damage = self._seal_check.wait()
                if damage is not None:
                    self._broken = str(damage)
                    if not self._seal_check.reported:
                        raise damage
            if self._unsynced and self._broken is None:
                self._sync()
            if self._broken is None:
                self._mark_durable()
        finally:
            self._closed = True
            os.close(self._fd)
            os.close(self._lock_fd)

    def __enter__(self) -> EventLog:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else f"last_seq={self._at.seq}"
        return f"EventLog({str(self._directory)!r}, stream={self._meta.stream!r}, {state})"

    def _check_usable(self) -> None:
        if self._closed:
            raise LogClosedError(f"event log {self._directory} is closed")
        if self._seal_check is not None:
            self._seal_check.result()  # raises CorruptLogError, every time, if a seal failed
            self._seal_check = None
        if self._broken is not None:
            raise LogClosedError(
                f"event log {self._directory} refuses appends after a failed write "
                f"({self._broken}); reopen it to recover"
            )

    def _write(self, data: bytes) -> None:
        """The rest of a record after a short write."""
        try:
            _fs.write_all(self._fd, data)
        except BaseException as exc:
            self._undo_write(exc)
            raise

    def _undo_write(self, exc: BaseException) -> None:
        # A partial line left in place would turn the next append into mid-file corruption.
        try:
            os.ftruncate(self._fd, self._at.offset)
        except OSError as cut_exc:
            self._broken = f"write failed ({exc!r}) and undoing it failed ({cut_exc!r})"

    def _seal(self) -> None:
        """Add the records written since the last call to the seals."""
        if self._unsealed:
            self._sealer.add_all(self._unsealed)
            self._unsealed = []

    def _sync(self) -> None:
        self._seal()
        try:
            os.fsync(self._fd)
            if os.fstat(self._fd).st_nlink == 0:
                raise LogClosedError(
                    f"{self._directory / LOG_FILE} was deleted while it was open for writing; "
                    "the events since the last fsync are only in the deleted file"
                )
        except BaseException as exc:
            # After a failed fsync the kernel may drop the dirty pages and report success on the
            # next try, so nothing written since the last good fsync can be trusted any more.
            self._broken = f"fsync failed: {exc!r}"
            raise
        self._unsynced = False
        if self._sealer.closed_count > self._sealed_in_mark:
            # A range was sealed: record it now, so a restart after a crash checks it by CRC.
            self._mark_durable()

    def _mark_durable(self) -> None:
        at = self._at
        mark = self.position
        if at.seq == 0 or (mark == self._durable and not self._attest_pending):
            return
        self._seal()
        write_durable(self._directory, mark, self._sealer.seals(), self._attested)
        self._durable = mark
        self._sealed_in_mark = self._sealer.closed_count
        self._attest_pending = False

    def attest_snapshot(self, seq: int, digest: str) -> None:
        """Record that the snapshot file with SHA-256 ``digest`` is the fold of this log up to
        ``seq`` (written to ``durable.json`` at :meth:`close`): a restore trusts only snapshots
        attested here, so one edited and re-checksummed by hand is rebuilt, not believed."""
        self._check_usable()
        if not 0 < seq <= self._at.seq:
            raise ValueError(f"seq {seq} is not in this log (1..{self._at.seq})")
        kept = [a for a in self._attested if a[1] != digest]
        self._attested = (*kept[-(MAX_ATTESTED - 1) :], (seq, digest))
        self._attest_pending = True


def _non_empty(path: Path) -> bool:
    try:
        return path.stat().st_size > 0
    except FileNotFoundError:
        return False


def _parse_uuid(value: object, what: str) -> uuid.UUID:
    try:
        return uuid.UUID(str(value))
    except ValueError:
        raise ValueError(f"{what} must be a UUID, got {value!r}") from None
