"""Bounds on an analyst's query: memory, threads, spill space, time.

DuckDB bounds its own buffers (``memory_limit``; beyond it, operators that can spill write to
``temp_directory``) but has no statement timeout, so :class:`Deadline` interrupts the connection
from a timer thread (``DuckDBPyConnection.interrupt``). The settings are applied before
:func:`objsearch.events.sql.lock_down` locks the configuration, so SQL cannot raise them.

DuckDB lets a query read its temp directory whatever ``allowed_directories`` says; its default is
``.tmp`` under the working directory, which would let a query read whatever lies there. So each
connection spills into a fresh private directory (``mkdtemp``: mode 0700, empty) that is removed
when the connection is garbage-collected or the process exits.

DuckDB's ``memory_limit`` covers its buffers, not the rows it hands to Python: a result fetched
row by row escaped both limits (``SELECT repeat('x', 1000000000)`` under 256 MB and 30 s ran
51 s and reached 7.0 GB, its rows held as Python objects). :class:`BoundedResult` fetches the
result as Arrow batches, counts their bytes against the connection's memory limit before any
becomes Python objects, converts them a slice at a time, and checks the deadline between
slices until it is closed, so the time limit covers the fetch and what the caller does with
the rows too. Not bounded: what DuckDB itself allocates to compute one vector of values (a
scalar function's result such as ``repeat``'s is not counted by its ``memory_limit``, and a
vector cannot be interrupted halfway), and one Arrow copy of that vector. ``objsearch query``
bounds those too: it runs the query in a process of its own whose memory is capped and which is
killed at the time limit (:mod:`objsearch.replay.query_process`).
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
import threading
import weakref
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, Final, Self

from .errors import EventStoreError
from .sql_quote import quote_literal

if TYPE_CHECKING:  # duckdb is imported when a connection is bounded, not by the CLI's parser
    import duckdb
    import pyarrow as pa

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
#: Each bounded connection's memory limit, which also bounds the result it hands to Python.
_MEMORY_LIMITS: weakref.WeakKeyDictionary[duckdb.DuckDBPyConnection, int] = (
    weakref.WeakKeyDictionary()
)
#: Rows of an Arrow batch of the result: DuckDB's vector, the least it produces at once.
RESULT_BATCH_ROWS: Final = 2048
#: Arrow bytes converted to Python objects at a time; the deadline is checked between slices.
_SLICE_BYTES: Final = 4 << 20


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
    check_limits(memory_limit, threads)
    temp = Path(tempfile.mkdtemp(prefix="objsearch-duckdb-"))
    _REMOVERS[con] = weakref.finalize(con, shutil.rmtree, temp, True)
    settings = [
        f"temp_directory = {quote_literal(str(temp))}",
        f"memory_limit = '{memory_limit}B'",
        f"max_temp_directory_size = '{SPILL_FACTOR * memory_limit}B'",
        f"threads = {threads}",
        # The result comes out as Arrow (BoundedResult): every DuckDB type kept (HUGEINT, UUID,
        # TIME WITH TIME ZONE, BIT, …), so its Python values are what DuckDB's own fetch gives.
        "arrow_lossless_conversion = true",
    ]
    for setting in settings:
        con.execute(f"SET {setting}")
    progress_bar_off(con)
    _MEMORY_LIMITS[con] = memory_limit
    return temp


def memory_limit_of(con: duckdb.DuckDBPyConnection) -> int | None:
    """The memory limit :func:`apply_limits` gave ``con`` (None: it did not bound it)."""
    return _MEMORY_LIMITS.get(con)


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
        return timed_out(self.timeout_s)

    def check(self) -> None:
        """Raise :class:`QueryLimitError` if the time is up."""
        if self.expired:
            raise self._timed_out()


class RowStream(ABC):
    """A query's rows in batches of Python tuples, closed on leaving a ``with`` block: what
    :class:`BoundedResult` (in process) and the query's own process
    (``objsearch.replay.query_process.QueryProcess``) share."""

    _rows: Iterator[list[tuple[Any, ...]]]

    def __iter__(self) -> Self:
        return self

    def __next__(self) -> list[tuple[Any, ...]]:
        return next(self._rows)

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @abstractmethod
    def close(self) -> None:
        """Stop the query and release what it holds (each kind of stream its own way)."""


class BoundedResult(RowStream):
    """The rows of ``sql`` on ``con``, in batches of Python tuples (the values DuckDB's own fetch
    gives), bounded by the connection's memory limit (:func:`memory_limit_of`) and by
    ``deadline`` until :meth:`close`.

    The result is read as Arrow batches of :data:`RESULT_BATCH_ROWS` rows; each batch's bytes are
    counted before any of it becomes Python objects: past the limit in one batch — or, with
    ``holds_all`` (a caller that keeps every row: a table to lay out, :func:`run_query`), in all
    of them together — the query stops with :class:`QueryLimitError`. A batch becomes Python a
    slice of about 4 MiB at a time, through a private in-memory DuckDB that reads nothing but the
    batch; the deadline is checked before each slice, and :meth:`check` lets the caller check
    it while it writes."""

    def __init__(
        self,
        con: duckdb.DuckDBPyConnection,
        sql: str,
        deadline: Deadline,
        *,
        holds_all: bool = False,
        batch_rows: int = RESULT_BATCH_ROWS,
    ) -> None:
        self.deadline = deadline
        self.holds_all = holds_all
        self.limit = memory_limit_of(con)
        self.held = 0
        self._limit_text = _memory_limit(con)
        self._reader: pa.RecordBatchReader | None = None
        self._convert: duckdb.DuckDBPyConnection | None = None
        try:
            with deadline.guard():
                relation = con.sql(sql)
                self.names: list[str] = [] if relation is None else list(relation.columns)
                if relation is not None:
                    self._reader = relation.to_arrow_reader(batch_rows)
            self._convert = converter()
        except BaseException:
            self.close()
            raise
        self._rows = self._batches()

    def check(self) -> None:
        """Raise :class:`QueryLimitError` if the time is up (for a caller writing the rows)."""
        self.deadline.check()

    def close(self) -> None:
        """Stop the deadline and let go of the result and the converter."""
        self.deadline.stop()
        if self._reader is not None:
            self._reader.close()
            self._reader = None
        if self._convert is not None:
            self._convert.close()
            self._convert = None

    def arrow_batches(self) -> Iterator[pa.RecordBatch]:
        """The result as Arrow batches, each counted against the memory limit (and the deadline
        checked) before it is yielded: what :mod:`objsearch.replay.query_process` sends from the
        query's process to the caller's, which makes them Python (:func:`python_rows`)."""
        while self._reader is not None and (batch := self._next_batch()) is not None:
            self._count(batch)
            self.deadline.check()
            yield batch
            if not self.holds_all:
                self.held = 0
        self.deadline.check()

    def _batches(self) -> Iterator[list[tuple[Any, ...]]]:
        for batch in self.arrow_batches():
            assert self._convert is not None
            yield from python_rows(self._convert, batch, self.deadline.check)

    def _next_batch(self) -> pa.RecordBatch | None:
        import duckdb
        import pyarrow as pa

        assert self._reader is not None
        try:
            return self._reader.read_next_batch()
        except StopIteration:
            return None
        except (duckdb.Error, pa.ArrowException, OSError) as exc:
            # DuckDB's errors reach the reader's caller through Arrow's stream (OSError, …)
            if self.deadline.expired:
                raise self.deadline._timed_out() from exc
            text = str(exc)
            if "Out of Memory Error" in text:
                raise QueryLimitError(
                    f"query exceeded its {self._limit_text} memory limit (raise it with "
                    f"--memory-limit): {text.splitlines()[0]}"
                ) from exc
            if isinstance(exc, duckdb.Error):
                raise
            raise duckdb.Error(text) from exc

    def _count(self, batch: pa.RecordBatch) -> None:
        self.held += batch.nbytes
        if self.limit is None or self.held <= self.limit:
            return
        what = (
            f"the {format_size(self.held)} of its rows held at once"
            if self.holds_all
            else f"one batch of {batch.num_rows:,} row(s), {format_size(batch.nbytes)}"
        )
        raise QueryLimitError(
            f"query exceeded its {self._limit_text} memory limit (raise it with "
            f"--memory-limit): the result needs more than that in objsearch: {what}"
        )


def timed_out(timeout_s: float | None) -> QueryLimitError:
    """The error of a query stopped at its time limit."""
    return QueryLimitError(
        f"query exceeded its {timeout_s:g} s time limit (raise it with --timeout)"
    )


def converter() -> duckdb.DuckDBPyConnection:
    """A private in-memory DuckDB that turns Arrow batches into DuckDB's own Python values
    (:func:`python_rows`): it reads nothing but the batch it is given."""
    import duckdb

    con = duckdb.connect(":memory:")
    for setting in (
        "threads = 1",
        "enable_external_access = false",
        "autoload_known_extensions = false",
        "lock_configuration = true",
    ):
        con.execute(f"SET {setting}")
    return con


def python_rows(
    convert: duckdb.DuckDBPyConnection, batch: pa.RecordBatch, check: Callable[[], None]
) -> Iterator[list[tuple[Any, ...]]]:
    """``batch`` as Python tuples through ``convert`` (:func:`converter`), a slice of about
    4 MiB at a time, calling ``check`` (the deadline) before each slice."""
    step = max(1, batch.num_rows * _SLICE_BYTES // max(1, batch.nbytes))
    for start in range(0, batch.num_rows, step):
        check()
        yield convert.from_arrow(batch.slice(start, step)).fetchall()


def _memory_limit(con: duckdb.DuckDBPyConnection) -> str:
    import duckdb

    try:  # fetchall: a result left unfinished would keep the connection from the next query
        rows = con.execute("SELECT current_setting('memory_limit')").fetchall()
    except duckdb.Error:
        return "memory"
    return str(rows[0][0]) if rows else "memory"
