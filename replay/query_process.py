"""An analyst's query in a process of its own: a hard bound on its memory and its time.

DuckDB's ``memory_limit`` bounds its buffer manager only: what a scalar function allocates
(``repeat('x', 1000000000)``'s gigabyte) is outside it, and an expression is interrupted only
between vectors, so in-process limits (:mod:`objsearch.events.sql_limits`) let that query run
53 s and reach 2.1 GB under ``--timeout 30 --memory-limit 256MB``. :class:`QueryProcess` runs
the query — the lake's views, DuckDB's work and the fetch of its rows as Arrow — in a child
interpreter (``python -m objsearch.replay.query_process``) that

* caps its data segment (``RLIMIT_DATA``: every private writable mapping, the heap and each
  ``mmap`` of the allocators) at what it holds once the lake's views are made plus the memory
  limit plus :data:`HEADROOM`, so an allocation past it fails (DuckDB says "Out of Memory
  Error", which ends as the usual memory-limit error) instead of growing; Arrow's allocator is
  the system's (``ARROW_DEFAULT_MEMORY_POOL=system``: mimalloc reserves a 1 GiB arena up front,
  which would count as held);
* is killed (SIGKILL) if it has not answered :data:`KILL_GRACE_S` after the time limit (its own
  timer interrupts DuckDB at the limit, which a long expression does not notice);
* spills into a private folder the parent makes and removes, killed or not;
* dies with the process that started it (Linux: ``PR_SET_PDEATHSIG``, :func:`die_with_parent`),
  so a query never outlives the command that asked it, even one killed with SIGKILL.

The rows come back as Arrow IPC over a pipe, one batch at a time (each counted against the
memory limit in the child before it is sent, :class:`~objsearch.events.sql_limits.BoundedResult`),
and become Python in the parent exactly as in-process (:func:`~objsearch.events.sql_limits.
python_rows`), so a query that fits prints the same bytes. The time limit starts when the
views are made (as in-process: opening the lake, hashing new data files, is not the query's)
and runs until the result is closed. Log records of the child (a damaged data file left out)
are logged again by the parent under their own logger.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import re
import selectors
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Final

from objsearch.events.errors import ObjsearchError
from objsearch.events.sql_limits import (
    DEFAULT_THREADS,
    QueryLimitError,
    RowStream,
    format_size,
    timed_out,
)

if TYPE_CHECKING:
    import duckdb
    import pyarrow as pa

#: What the query's process may allocate beyond the memory limit once the lake's views are made:
#: DuckDB's work outside its buffers, the result batch being sent, Python's own.
HEADROOM: Final = 256 << 20
#: How long after the time limit the query's process may take to say so itself before it is killed.
KILL_GRACE_S: Final = 1.0
#: A frame: its kind (one byte) and the length of what follows.
_FRAME: Final = struct.Struct("<cQ")
_READY, _NAMES, _BATCH, _DONE, _ERROR, _LOG = b"R", b"N", b"B", b"D", b"E", b"L"
#: The environment variable that gives the query's process the pid of the process it answers.
_PARENT: Final = "OBJSEARCH_QUERY_PARENT"
#: Linux's prctl option: the signal a process gets when the thread that started it ends.
_PR_SET_PDEATHSIG: Final = 1


@dataclass(frozen=True, slots=True)
class QueryRequest:
    """What the query's process runs: ``sql`` over the lake at ``lake`` (a folder or an
    ``s3://`` address), within ``memory_limit`` bytes and ``timeout_s`` seconds (None: none);
    ``holds_all``: the caller keeps every row (a table), so they count together."""

    lake: str
    sql: str
    memory_limit: int
    timeout_s: float | None
    holds_all: bool = False
    threads: int = DEFAULT_THREADS


class QueryProcess(RowStream):
    """The rows of a :class:`QueryRequest`, in batches of Python tuples, from a child process
    bounded as the module says; :attr:`names` are the columns. Raises what the in-process query
    would (:class:`~objsearch.events.sql_limits.QueryLimitError`, DuckDB's own error class,
    :class:`~objsearch.events.sql.QueryRefusedError`, the lake's
    :class:`~objsearch.events.errors.ObjsearchError`, ``OSError``). Close it (or ``with`` it):
    that kills the process if it still runs and removes its spill folder. Make it in a thread that
    outlives it: on Linux the process is killed when the thread that started it ends."""

    def __init__(self, request: QueryRequest) -> None:
        from objsearch.events.sql_limits import converter

        self.request = request
        self.names: list[str] = []
        self._deadline: float | None = None
        self._ready = False
        self._killed = False
        self._limit_text = format_size(request.memory_limit)  # DuckDB's way, once it says it
        self._done = False
        self._private = Path(tempfile.mkdtemp(prefix="objsearch-query-"))
        self._convert: duckdb.DuckDBPyConnection | None = None
        env = os.environ | {
            "TMPDIR": str(self._private),
            "ARROW_DEFAULT_MEMORY_POOL": "system",
            _PARENT: str(os.getpid()),
        }
        # -P: a module in the working folder never shadows the package or DuckDB
        self._proc = subprocess.Popen(
            [sys.executable, "-P", "-m", __name__],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            env=env,
            bufsize=0,
        )
        try:
            assert self._proc.stdin is not None and self._proc.stdout is not None
            self._out: IO[bytes] = self._proc.stdout
            self._proc.stdin.write(json.dumps(asdict(request)).encode())
            self._proc.stdin.close()
            self._convert = converter()
            kind, payload = self._next_frame()
            if kind != _NAMES:
                raise RuntimeError(f"the query's process sent {kind!r} before its columns")
            self.names = json.loads(payload)
        except BaseException:
            self.close()
            raise
        self._rows = self._batches()

    def check(self) -> None:
        """Raise :class:`QueryLimitError` if the time is up (for a caller writing the rows)."""
        if self._deadline is not None and time.monotonic() >= self._deadline:
            raise timed_out(self.request.timeout_s)

    def close(self) -> None:
        """Kill the process if it still runs (one that sent all its rows is given a moment to
        close its connection), wait for it, remove its spill folder."""
        if self._done:
            with contextlib.suppress(subprocess.TimeoutExpired):
                self._proc.wait(timeout=KILL_GRACE_S)
        if self._proc.poll() is None:
            self._kill()
        self._proc.wait()
        self._out.close()
        if self._convert is not None:
            self._convert.close()
            self._convert = None
        shutil.rmtree(self._private, ignore_errors=True)

    def _kill(self) -> None:
        self._killed = True
        self._proc.kill()

    def _batches(self) -> Iterator[list[tuple[Any, ...]]]:
        import pyarrow as pa

        from objsearch.events.sql_limits import python_rows

        while not self._done:
            kind, payload = self._next_frame()
            if kind == _DONE:
                self._done = True
                break
            if kind != _BATCH:
                raise RuntimeError(f"the query's process sent {kind!r} among its rows")
            batch = pa.ipc.open_stream(pa.py_buffer(payload)).read_next_batch()
            del payload
            assert self._convert is not None
            yield from python_rows(self._convert, batch, self.check)
        self.check()

    def _next_frame(self) -> tuple[bytes, bytearray]:
        """The next frame but a log record (those are logged here): its kind and bytes; an
        error frame is raised."""
        while True:
            kind, size = _FRAME.unpack(self._read(_FRAME.size))
            payload = self._read(size)
            if kind == _LOG:
                record = json.loads(payload)
                logging.getLogger(record["name"]).log(record["level"], "%s", record["message"])
            elif kind == _READY:
                self._ready = True
                self._limit_text = json.loads(payload)["memory_limit"]
                if self.request.timeout_s is not None:
                    self._deadline = time.monotonic() + self.request.timeout_s
            elif kind == _ERROR:
                doc = json.loads(payload)
                if doc["kind"] == "duckdb" and "Out of Memory Error" in doc["message"]:
                    # Wherever DuckDB ran out (its buffer manager's refusal, or an allocation
                    # failing under the process's cap: "Allocation failure"), the limit was hit.
                    raise QueryLimitError(
                        f"query exceeded its {self._limit_text} memory limit (raise it with "
                        f"--memory-limit): {doc['message'].splitlines()[0]}"
                    )
                raise _error(doc)
            else:
                return kind, payload

    def _read(self, size: int) -> bytearray:
        """``size`` bytes from the process, waiting no longer than the time limit and its grace;
        the process gone or killed before they came is raised as the error it means."""
        data = bytearray(size)
        view = memoryview(data)
        got = 0
        with selectors.DefaultSelector() as selector:
            selector.register(self._out, selectors.EVENT_READ)
            while got < size:
                wait = None
                if self._deadline is not None:
                    wait = self._deadline + KILL_GRACE_S - time.monotonic()
                if (wait is not None and wait <= 0) or not selector.select(wait):
                    self._kill()
                    self._proc.wait()
                    raise timed_out(self.request.timeout_s)
                n = os.readv(self._out.fileno(), [view[got:]])
                if not n:
                    raise self._ended()
                got += n
        return data

    def _ended(self) -> QueryLimitError | RuntimeError:
        """The error of a process that ended without an answer."""
        code = self._proc.wait()
        if self._killed:
            return timed_out(self.request.timeout_s)
        how = f"killed by signal {-code}: {signal.strsignal(-code)}" if code < 0 else f"exit {code}"
        if code == 1 or not self._ready:  # an uncaught exception, or before the cap: a bug
            return RuntimeError(
                f"the query's process ended without an answer ({how}; its traceback, if any, "
                "is above)"
            )
        return QueryLimitError(
            f"query exceeded its {self._limit_text} memory limit (raise it with "
            f"--memory-limit): its process ended without an answer ({how}); it may hold that "
            f"much plus {format_size(HEADROOM)} beyond what the lake's views take"
        )


def _error(doc: dict[str, Any]) -> BaseException:
    """The exception the query's process reported."""
    import duckdb

    from objsearch.events.sql import QueryRefusedError

    kind, message = doc["kind"], doc["message"]
    if kind == "limit":
        return QueryLimitError(message)
    if kind == "refused":
        return QueryRefusedError(message)
    if kind == "objsearch":
        return ObjsearchError(message)
    if kind == "os":
        return OSError(doc["errno"], doc["strerror"], doc["filename"])
    if kind == "duckdb":
        cls = getattr(duckdb, doc["class"], duckdb.Error)
        if isinstance(cls, type) and issubclass(cls, duckdb.Error):
            return cls(message)
        return duckdb.Error(message)
    raise ValueError(f"unknown error kind {kind!r} from the query's process")


# The query's process -----------------------------------------------------------------------


class _Channel:
    """The frames to the parent, on the stdout it was given (stdout itself then points at
    stderr, so nothing printed can get between the frames)."""

    def __init__(self) -> None:
        self.out = os.fdopen(os.dup(1), "wb")
        os.dup2(2, 1)

    def send(self, kind: bytes, payload: bytes = b"") -> None:
        self.out.write(_FRAME.pack(kind, len(payload)))
        self.out.write(payload)
        self.out.flush()

    def send_json(self, kind: bytes, doc: Any) -> None:
        self.send(kind, json.dumps(doc).encode())

    def send_batch(self, batch: pa.RecordBatch) -> None:
        """``batch`` as an Arrow IPC stream of its own, written straight from its buffers."""
        import pyarrow as pa

        sized = pa.MockOutputStream()
        with pa.ipc.new_stream(sized, batch.schema) as writer:
            writer.write_batch(batch)
        self.out.write(_FRAME.pack(_BATCH, sized.size()))
        sink = pa.PythonFile(self.out, mode="w")
        with pa.ipc.new_stream(sink, batch.schema) as writer:
            writer.write_batch(batch)
        self.out.flush()


class _Forward(logging.Handler):
    def __init__(self, channel: _Channel) -> None:
        super().__init__(logging.WARNING)
        self.channel = channel

    def emit(self, record: logging.LogRecord) -> None:
        doc = {"name": record.name, "level": record.levelno, "message": record.getMessage()}
        self.channel.send_json(_LOG, doc)


def cap_memory(memory_limit: int) -> int | None:
    """Cap this process's data segment at what it holds now plus ``memory_limit`` plus
    :data:`HEADROOM` (never above a cap it had); the cap, or None where ``/proc`` does not say
    what it holds (not Linux: no cap)."""
    import resource

    try:
        status = Path("/proc/self/status").read_text(encoding="ascii")
    except OSError:
        return None
    found = re.search(r"^VmData:\s+(\d+) kB", status, re.MULTILINE)
    if found is None:
        return None
    cap = int(found[1]) * 1024 + memory_limit + HEADROOM
    soft, hard = resource.getrlimit(resource.RLIMIT_DATA)
    for old in (soft, hard):
        if old != resource.RLIM_INFINITY:
            cap = min(cap, old)
    resource.setrlimit(resource.RLIMIT_DATA, (cap, hard))
    return cap


def serve(request: QueryRequest, channel: _Channel) -> None:
    """Run ``request`` and send its frames: log records, ready, columns, batches, done."""
    from objsearch.events.sql_limits import close
    from objsearch.replay.analytics import open_analytics, stream_query

    con = open_analytics(
        request.lake,
        memory_limit=request.memory_limit,
        threads=request.threads,
        for_sql=request.sql,
    )
    try:
        cap_memory(request.memory_limit)
        [(limit,)] = con.execute("SELECT current_setting('memory_limit')").fetchall()
        channel.send_json(_READY, {"memory_limit": limit})
        names, result = stream_query(
            con, request.sql, timeout_s=request.timeout_s, holds_all=request.holds_all
        )
        channel.send_json(_NAMES, names)
        with result:
            for batch in result.arrow_batches():
                channel.send_batch(batch)
        channel.send(_DONE)
    finally:
        close(con)


def _report(exc: BaseException) -> dict[str, Any] | None:
    """An exception of the query's process as the parent raises it again (:func:`_error`); None
    for one no query is expected to raise (a bug: the process ends with its traceback)."""
    import duckdb

    from objsearch.events.sql import QueryRefusedError

    if isinstance(exc, QueryLimitError):
        return {"kind": "limit", "message": str(exc)}
    if isinstance(exc, QueryRefusedError):
        return {"kind": "refused", "message": str(exc)}
    if isinstance(exc, ObjsearchError):
        return {"kind": "objsearch", "message": str(exc)}
    if isinstance(exc, duckdb.Error):
        return {"kind": "duckdb", "class": type(exc).__name__, "message": str(exc)}
    if isinstance(exc, OSError) and exc.errno is not None:
        filename = None if exc.filename is None else os.fsdecode(exc.filename)
        return {"kind": "os", "errno": exc.errno, "strerror": exc.strerror, "filename": filename}
    return None


def die_with_parent() -> None:
    """Be killed (SIGKILL) when the process that started this one ends, even by SIGKILL, so a
    query never outlives the command that asked it (Linux: ``PR_SET_PDEATHSIG``; elsewhere the
    query's own timer and its broken pipe end it). Exits now if that process is already gone."""
    import ctypes

    parent = int(os.environ.get(_PARENT, "0"))
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        prctl = libc.prctl
    except (OSError, AttributeError):  # not Linux
        return
    if prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0 and os.getppid() != parent:
        os._exit(1)


def main() -> int:
    import duckdb

    die_with_parent()
    channel = _Channel()
    logging.basicConfig(handlers=[_Forward(channel)], level=logging.WARNING, force=True)
    request = QueryRequest(**json.loads(sys.stdin.buffer.read()))
    try:
        serve(request, channel)
    except MemoryError:
        message = (
            f"query exceeded its {format_size(request.memory_limit)} memory limit (raise it "
            "with --memory-limit): objsearch ran out of memory holding its result"
        )
        channel.send_json(_ERROR, {"kind": "limit", "message": message})
    except BrokenPipeError:  # the parent stopped reading: it has its answer
        return 0
    except (ObjsearchError, duckdb.Error, OSError) as exc:
        report = _report(exc)
        if report is None:
            raise
        channel.send_json(_ERROR, report)
    return 0


if __name__ == "__main__":
    code = main()
    # The answer is sent (every frame flushed) and DuckDB's connection closed: what is left is
    # the interpreter's teardown, freeing what DuckDB, Arrow and numpy hold, 0.1-0.4 s that the
    # command waits for (QueryProcess.close) before it can remove the spill folder. Leave without
    # it. A bug still ends the usual way: main raises, and Python prints its traceback.
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
