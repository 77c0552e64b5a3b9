"""The seal check: every byte of ``events.log`` before the durable high-water mark compared with
the seals in ``durable.json`` (CRC-32 of whole ranges, no parsing). A writer's fast open
(``verify="sealed"``) runs it on a thread of its own (:class:`_SealCheck`) while the caller
restores its state; a full open and ``objsearch log verify``/``repair`` run it in line
(:func:`_check_sealed`). Where a seal does not match, the records are parsed to name the first
damaged one, so the error is the one every reader gives.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from .errors import CorruptLogError
from .log_files import DURABLE_FILE, LOG_FILE, META_FILE, DurableRecord, LogMeta
from .scan import _Scan
from .schemas import SchemaRegistry
from .seal import check_seals


class _SealCheck:
    """:func:`_check_sealed` on a thread of its own; :meth:`result` waits and raises what it
    found (``reported`` once it has)."""

    def __init__(
        self, directory: Path, meta: LogMeta, registry: SchemaRegistry, record: DurableRecord
    ) -> None:
        self._directory = directory
        self.reported = False
        pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="seal-check")
        self._check = pool.submit(_check_sealed, directory, meta, registry, record)
        pool.shutdown(wait=False)

    def wait(self) -> CorruptLogError | None:
        """The damage found, or None; any other error of the check is raised here (a bug is never
        appended on, nor hidden)."""
        error = self._check.exception()
        if error is None or isinstance(error, CorruptLogError):
            return error
        if isinstance(error, (OSError, ValueError)):  # an unreadable file is damage too
            return CorruptLogError(
                f"corrupt event log {self._directory / LOG_FILE}: its seals could not be checked "
                f"({error!r}); the log was not changed",
                path=str(self._directory / LOG_FILE),
                line=0,
                offset=0,
            )
        raise error

    def result(self) -> None:
        damage = self.wait()
        if damage is not None:
            self.reported = True
            raise damage


def _check_sealed(
    directory: Path, meta: LogMeta, registry: SchemaRegistry, record: DurableRecord
) -> None:
    """Raise :class:`CorruptLogError` unless every seal of ``record`` matches ``events.log``.

    Where one does not, the records are parsed to name the first damaged one (the error every
    reader gives); if they all verify, the seals themselves are what is damaged."""
    assert record.seals is not None
    path = directory / LOG_FILE
    bad = check_seals(path, record.seals, meta.genesis)
    if bad is None:
        return
    scan = _Scan(path, meta, registry=registry, durable=record.position, payloads=False)
    for _ in scan:
        pass
    raise CorruptLogError(
        f"corrupt event log {path}: bytes {bad.start}..{bad.end} do not match their seal "
        f"(CRC-32 {bad.crc:08x} in {DURABLE_FILE}, the first one seeded from {META_FILE}) "
        f"though every record there verifies: {DURABLE_FILE} is damaged; the log was not "
        "changed (`objsearch log repair` rewrites it)",
        path=str(directory / DURABLE_FILE),
        line=0,
        offset=bad.start,
    )
