"""A torn tail: the unterminated fragment an interrupted append leaves after the last newline of
``events.log``, never acknowledged. A reader skips it and reports it (a :class:`TornTailWarning`
and a warning on the ``objsearch.events.log`` logger, :func:`_report`); the writer, on opening,
keeps it in a quarantine file beside the log and then cuts it (:func:`_cut_torn_tail`: the only
change a writer makes to existing bytes). :func:`quarantine` is how any bytes leave the log
without being lost: the writer's cut, and ``objsearch log repair``.
"""

from __future__ import annotations

import logging
import os
import warnings
from pathlib import Path

from . import _fs
from .errors import TornTailWarning
from .log_files import QUARANTINE_PREFIX, TornTail

# The logger of the log before it was split: what callers and tests filter torn-tail reports by.
_log = logging.getLogger("objsearch.events.log")

__all__ = ["quarantine"]


def _cut_torn_tail(fd: int, tail: TornTail) -> TornTail:
    # The only modification a writer makes to existing bytes, never silent, and never a loss:
    # the fragment is kept beside the log before the file is cut.
    with tail.path.open("rb") as f:
        f.seek(tail.offset)
        fragment = f.read()
    keep = quarantine(tail.path.parent, f"torn-{tail.offset}", fragment)
    _report(
        f"torn tail in {tail.path}: cut {tail.length} byte(s) at byte offset {tail.offset} "
        f"(line {tail.line}; {tail.reason}); an interrupted append, never acknowledged; "
        f"the bytes are kept in {keep}",
        stacklevel=5,
    )
    os.ftruncate(fd, tail.offset)
    os.fsync(fd)
    return TornTail(
        path=tail.path, offset=tail.offset, length=tail.length, line=tail.line, quarantine=keep
    )


def quarantine(directory: Path, label: str, data: bytes) -> Path:
    """Keep ``data`` durably in a new file ``events.log.<label>[.N]`` of ``directory``."""
    path = directory / f"{QUARANTINE_PREFIX}{label}"
    n = 0
    while path.exists():
        n += 1
        path = directory / f"{QUARANTINE_PREFIX}{label}.{n}"
    _fs.write_new(path, data)
    return path


def _report(message: str, *, stacklevel: int) -> None:
    _log.warning("%s", message)
    warnings.warn(message, TornTailWarning, stacklevel=stacklevel)
