"""``objsearch query``'s process forked from a warm one, for the tests that run hundreds of queries.

``objsearch query`` runs its SQL in a process of its own (``python -P -m
objsearch.replay.query_process``, :class:`objsearch.replay.query_process.QueryProcess`): a fresh
interpreter that imports DuckDB, Arrow, numpy and the lake's reader before it reads the lake,
about 0.27 s of its 0.45 s on an idle machine. The lake batteries ask the same lake questions
over a hundred times (``tests/test_lake_log_battery.py``: 102 queries), as does
``tests/test_cli_query.py`` (96), so that start-up was most of their time. As
:class:`devtools.killtest.KillServer` does for the kill tests, :class:`QueryServer` is one
process that has imported what the query's process imports (and nothing it would not: its memory
cap is taken from what it holds) and forks a child per query; the child runs the
query process's own ``main`` on the pipes the command made, with the command's environment, in
its working folder, and leaves as that process leaves (``os._exit`` with ``main``'s code, or 1
with the traceback of a bug). The command (``QueryProcess``) is unchanged: :func:`forked_queries`
hands it, in place of ``subprocess.Popen``, an object that starts its process through the server
(:class:`Forked`: the same pipes, ``poll``, ``wait``, ``kill``, exit codes as Popen's). So the
child gets its memory cap, time limit, spill folder and death with the server (which dies with
the process that started it) as the real one does; only the interpreter's start is shared.

What a fresh interpreter alone can show (the command line of the process, its ``-P``, the module
run as ``__main__``, its memory and time limits as shipped) is tested without the server:
``tests/replay/test_query_process.py`` and the tests of the query's limits, spill folder and
defaults in ``tests/test_cli_query.py`` (its ``FRESH_PROCESS``) start the real process.

One query at a time per server (the batteries ask one after another): a second started before the
first one's process has ended is refused.
"""

from __future__ import annotations

import atexit
import contextlib
import json
import os
import select
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator, Mapping, Sequence
from typing import IO, Any, Final

#: The command line ``QueryProcess`` starts its process with.
QUERY_MODULE: Final = "objsearch.replay.query_process"
_PARENT: Final = "OBJSEARCH_QUERY_PARENT"

_SERVER: Final = r"""
import json, os, socket, sys, tempfile, traceback
from objsearch.replay import query_process
# what the query's process imports to answer (query_process.main, serve, _report, the lake's read)
import resource, duckdb, deltalake, deltalake.table, pyarrow, pyarrow.ipc, pyarrow.dataset
import pyarrow.compute, pyarrow.acero
import objsearch.events.sql, objsearch.events.sql_limits, objsearch.replay.analytics
query_process.die_with_parent()  # the server dies with the process that started it
channel = socket.socket(fileno=int(sys.argv[1]))
while True:
    message, fds, _, _ = socket.recv_fds(channel, 1 << 20, 3)
    if not message:
        break
    job = json.loads(message)
    pid = os.fork()
    if pid == 0:
        channel.close()
        os.dup2(fds[0], 0)
        os.dup2(fds[1], 1)
        os.dup2(fds[2], 2)
        for fd in fds:
            os.close(fd)
        os.chdir(job["cwd"])
        os.environ.clear()
        os.environ.update(job["env"])
        os.environ[query_process._PARENT] = str(os.getppid())  # the server
        tempfile.tempdir = None  # read $TMPDIR (the query's spill folder) again
        code = 1
        try:
            code = query_process.main()
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
        except BaseException:
            traceback.print_exc()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    for fd in fds:
        os.close(fd)
    channel.send(b"%d" % pid)
    _, status = os.waitpid(pid, 0)
    channel.send(b"%d" % os.waitstatus_to_exitcode(status))
"""


class QueryServer:
    """The warm process the queries are forked from (started at once; :meth:`close` ends it)."""

    def __init__(self) -> None:
        self._channel, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        env = os.environ | {"ARROW_DEFAULT_MEMORY_POOL": "system", _PARENT: str(os.getpid())}
        with theirs:
            self._proc = subprocess.Popen(
                [sys.executable, "-P", "-c", _SERVER, str(theirs.fileno())],
                stdin=subprocess.DEVNULL,
                pass_fds=[theirs.fileno()],
                env=env,
            )
        self.busy: Forked | None = None

    @property
    def alive(self) -> bool:
        return self._proc.poll() is None

    def start(self, env: Mapping[str, str], cwd: str) -> tuple[int, IO[bytes], IO[bytes]]:
        """Fork a query's process (its stderr this process's): its pid, and the write end of its
        stdin and the read end of its stdout (unbuffered, as ``Popen(..., bufsize=0)`` gives
        them)."""
        if self.busy is not None and self.busy.returncode is None:
            raise RuntimeError("the query server runs one query at a time; close the first one")
        stdin_r, stdin_w = os.pipe()
        stdout_r, stdout_w = os.pipe()
        try:
            job = json.dumps({"env": dict(env), "cwd": cwd}).encode()
            # and the stderr the command has now, which a fresh process would inherit
            socket.send_fds(self._channel, [job], [stdin_r, stdout_w, 2])
        finally:
            os.close(stdin_r)
            os.close(stdout_w)
        pid = int(self._reply(None) or b"0")
        if not pid:
            os.close(stdin_w)
            os.close(stdout_r)
            raise RuntimeError("the query server ended; see its traceback above")
        return pid, open(stdin_w, "wb", buffering=0), open(stdout_r, "rb", buffering=0)

    def _reply(self, timeout: float | None) -> bytes | None:
        """The server's next message, None if none came within ``timeout`` seconds; b"" once
        the server is gone."""
        ready, _, _ = select.select([self._channel], [], [], timeout)
        if not ready:
            return None
        return self._channel.recv(64)

    def close(self) -> None:
        self._channel.close()  # the server reads an end and leaves
        try:
            self._proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()


class Forked:
    """What ``QueryProcess`` uses of a ``subprocess.Popen``, for a process forked by a
    :class:`QueryServer`: ``stdin``, ``stdout``, ``pid``, ``returncode``, ``poll``, ``wait``,
    ``kill`` (its exit code comes from the server, which is its parent)."""

    def __init__(self, server: QueryServer, args: Sequence[str], env: Mapping[str, str]) -> None:
        self.args = list(args)
        self.returncode: int | None = None
        self._server = server
        self.pid, self.stdin, self.stdout = server.start(env, os.getcwd())
        server.busy = self

    def poll(self) -> int | None:
        if self.returncode is None:
            self._take(self._server._reply(0))
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        if self.returncode is None:
            self._take(self._server._reply(timeout))
        if self.returncode is None:
            assert timeout is not None
            raise subprocess.TimeoutExpired(self.args, timeout)
        return self.returncode

    def kill(self) -> None:
        if self.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.pid, signal.SIGKILL)

    def _take(self, reply: bytes | None) -> None:
        if reply is None:
            return
        if not reply:
            raise RuntimeError("the query server ended before its query's process did")
        self.returncode = int(reply)


_server: list[QueryServer] = []


def _the_server() -> QueryServer:
    """This process's server, started on first use (and again if it has ended)."""
    if not _server or not _server[0].alive:
        close_server()
        _server.append(QueryServer())
    return _server[0]


def close_server() -> None:
    """End this process's server, if it has one (the next query starts another)."""
    while _server:
        _server.pop().close()


atexit.register(close_server)


@contextlib.contextmanager
def forked_queries() -> Iterator[None]:
    """Within it, every ``objsearch query`` run in this process forks its query's process from
    this process's :class:`QueryServer`; any other process starts as usual."""
    popen = subprocess.Popen

    def start(args: Any, *rest: Any, **kwargs: Any) -> Any:
        if list(args)[-2:] != ["-m", QUERY_MODULE]:
            return popen(args, *rest, **kwargs)
        assert not rest and kwargs.get("stdin") == kwargs.get("stdout") == subprocess.PIPE
        assert kwargs.get("bufsize") == 0 and set(kwargs) <= {"stdin", "stdout", "env", "bufsize"}
        return Forked(_the_server(), args, kwargs.get("env") or os.environ)

    setattr(subprocess, "Popen", start)  # noqa: B010  (replay/query_process.py calls it so)
    try:
        yield
    finally:
        setattr(subprocess, "Popen", popen)  # noqa: B010
