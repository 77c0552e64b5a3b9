"""Bounds on an analyst's query: memory, threads, spill space, time.

DuckDB bounds its own buffers (``memory_limit``; beyond it, operators that can spill write to
``temp_directory``) but has no statement timeout, so :class:`Deadline` interrupts the connection
from a timer thread (``DuckDBPyConnection.interrupt``). The settings are applied before
:func:`objsearch.events.sql.lock_down` locks the configuration, so SQL cannot raise them.

DuckDB lets a query read its temp directory whatever ``allowed_directories`` says; its default is
``.tmp`` under the working directory, which would let a query read whatever lies there. So each
connection spills into a fresh private directory (``mkdtemp``: mode 0700, empty) that is removed
when the connection is garbage-collected or the process exits.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
import threading
import weakref
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from .errors import EventStoreError

if TYPE_CHECKING:  # duckdb is imported when a connection is bounded, not by the CLI's parser
    import duckdb

#: Defaults that protect a shared machine; ``objsearch query`` raises them with --memory-limit
#: and --timeout.
DEFAULT_MEMORY_LIMIT: Final = 1 << 30
DEFAULT_TIMEOUT_S: Final = 60.0
#: DuckDB's own default (every core), capped at 4: a query on a big shared machine leaves the
#: other cores to the others; on a small one it is as fast as before.
DEFAULT_THREADS: Final = max(1, min(4, os.cpu_count() or 1))
#: Spill space a query may use, as a multiple of its memory limit.
SPILL_FACTOR: Final = 8
MIN_MEMORY_LIMIT: Final = 16 << 20
MAX_MEMORY_LIMIT: Final = 1 << 40
_UNITS: Final = {
    "": 1,
    "b": 1,
    "kb": 10**3,
    "mb": 10**6,
    "gb": 10**9,
    "tb": 10**12,
    "kib": 1 << 10,
    "mib": 1 << 20,
    "gib": 1 << 30,
    "tib": 1 << 40,
}
_SIZE: Final = re.compile(r"\s*([0-9]+(?:\.[0-9]+)?)\s*([A-Za-z]*)\s*")


#: Each bounded connection's temp-directory remover (see :func:`close`).
_REMOVERS: weakref.WeakKeyDictionary[duckdb.DuckDBPyConnection, weakref.finalize[Any, Any]] = (
    weakref.WeakKeyDictionary()
)


class QueryLimitError(EventStoreError):
    """A query ran past its time or memory limit and was stopped."""


def parse_size(text: str) -> int:
    """Bytes from ``"1GB"``, ``"512 MiB"``, ``"2.5GiB"``, ``"1073741824"`` (decimal units are
    powers of 1000, binary ones of 1024, as DuckDB reads them); raises ValueError."""
    match = _SIZE.fullmatch(text)
    unit = match.group(2).lower() if match else ""
    if match is None or unit not in _UNITS:
        raise ValueError(f"expected a size such as 1GB, 512MiB or 2GiB, not {text!r}")
    return int(float(match.group(1)) * _UNITS[unit])


def format_size(size: int) -> str:
    for unit in ("TiB", "GiB", "MiB", "KiB", "TB", "GB", "MB", "KB"):
        scale = _UNITS[unit.lower()]
        if size >= scale and size % scale == 0:
            return f"{size // scale} {unit}"
    if size >= 1 << 20:
        return f"{size / (1 << 30):.2f} GiB" if size >= 1 << 30 else f"{size / (1 << 20):.1f} MiB"
    return f"{size} bytes"


def check_limits(memory_limit: int, threads: int) -> None:
    """Raise ValueError unless the limits are in range (the timeout is the caller's: the CLI
    checks its option's range)."""
    if not MIN_MEMORY_LIMIT <= memory_limit <= MAX_MEMORY_LIMIT:
        raise ValueError(
            f"memory limit must be between {format_size(MIN_MEMORY_LIMIT)} and "
            f"{format_size(MAX_MEMORY_LIMIT)}, not {format_size(memory_limit)}"
        )
    if threads < 1:
        raise ValueError(f"threads must be at least 1, not {threads}")


def apply_limits(con: duckdb.DuckDBPyConnection, *, memory_limit: int, threads: int) -> Path:
    """Bound the connection's memory, threads and spill space, and give it a private temp
    directory (returned); call before the configuration is locked."""
    from .sql import quote_literal

    check_limits(memory_limit, threads)
    temp = Path(tempfile.mkdtemp(prefix="objsearch-duckdb-"))
    _REMOVERS[con] = weakref.finalize(con, shutil.rmtree, temp, True)
    settings = [
        f"temp_directory = {quote_literal(str(temp))}",
        f"memory_limit = '{memory_limit}B'",
        f"max_temp_directory_size = '{SPILL_FACTOR * memory_limit}B'",
        f"threads = {threads}",
    ]
    for setting in settings:
        con.execute(f"SET {setting}")
    progress_bar_off(con)
    return temp


def progress_bar_off(con: duckdb.DuckDBPyConnection) -> None:
    """Turn DuckDB's progress bar off (it writes to the terminal). Under Jupyter DuckDB has it
    off already and refuses any change to it without ipywidgets (open_analytics in a notebook
    failed): turned off only where it is on."""
    if con.execute("SELECT current_setting('enable_progress_bar')").fetchall() != [(False,)]:
        con.execute("SET enable_progress_bar = false")


def close(con: duckdb.DuckDBPyConnection) -> None:
    """Close a connection :func:`apply_limits` bounded and remove its temp directory now
    (otherwise that happens when the connection is garbage-collected, or at exit)."""
    con.close()
    remover = _REMOVERS.pop(con, None)
    if remover is not None:
        remover()


class Deadline:
    """Interrupt ``con`` once ``timeout_s`` (None: never) has passed since creation, until
    :meth:`stop`; :meth:`guard` turns DuckDB's interrupt and out-of-memory errors into
    :class:`QueryLimitError`.

    The timer interrupts only before :meth:`stop` (a lock orders the two), so a late timer never
    interrupts the connection's next query."""

    def __init__(self, con: duckdb.DuckDBPyConnection, timeout_s: float | None) -> None:
        self.con = con
        self.timeout_s = timeout_s
        self.expired = False
        self._active = True
        self._lock = threading.Lock()
        self._timer: threading.Timer | None = None
        if timeout_s is not None:
            self._timer = threading.Timer(timeout_s, self._fire)
            self._timer.daemon = True
            self._timer.start()

    def _fire(self) -> None:
        with self._lock:
            if self._active:
                self.expired = True
                self.con.interrupt()

    def stop(self) -> None:
        with self._lock:
            self._active = False
        if self._timer is not None:
            self._timer.cancel()
            self._timer.join()  # prompt once cancelled; the thread no longer holds the connection
            self._timer = None

    @contextmanager
    def guard(self) -> Iterator[None]:
        import duckdb

        try:
            yield
        except duckdb.InterruptException as exc:
            if self.expired:
                raise self._timed_out() from exc
            raise
        except duckdb.OutOfMemoryException as exc:
            raise QueryLimitError(
                f"query exceeded its {_memory_limit(self.con)} memory limit (raise it with "
                f"--memory-limit): {str(exc).splitlines()[0]}"
            ) from exc
        if self.expired:
            raise self._timed_out()

    def _timed_out(self) -> QueryLimitError:
        return QueryLimitError(
            f"query exceeded its {self.timeout_s:g} s time limit (raise it with --timeout)"
        )


def _memory_limit(con: duckdb.DuckDBPyConnection) -> str:
    import duckdb

    try:
        row = con.execute("SELECT current_setting('memory_limit')").fetchone()
    except duckdb.Error:
        return "memory"
    return str(row[0]) if row else "memory"
