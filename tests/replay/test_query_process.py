"""An analyst's query in a process of its own (:mod:`objsearch.replay.query_process`): the same
rows and errors as in-process, and a process that dies is said, not a hang or a traceback."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import duckdb
import pytest

from objsearch.events.lake import TableLake
from objsearch.events.sql import QueryRefusedError
from objsearch.events.sql_limits import QueryLimitError, close
from objsearch.replay.analytics import open_analytics, run_query
from objsearch.replay.query_process import QueryProcess, QueryRequest

QUERIES = (
    "SELECT robot, run, count(*) AS n FROM events GROUP BY ALL ORDER BY ALL",
    "SELECT * FROM searches ORDER BY ALL",
    "SELECT 12345678901234567890::UHUGEINT AS h, TIMETZ '10:11:12+02' AS tz, MAP {'k': 1} AS m, "
    "'0101'::BIT AS b, [{'x': [1.5]}] AS nested, INTERVAL 3 DAY AS i",
)


def _request(lake: TableLake, sql: str, *, timeout_s: float | None = 300.0) -> QueryRequest:
    return QueryRequest(lake=str(lake.root), sql=sql, memory_limit=1 << 30, timeout_s=timeout_s)


@pytest.mark.parametrize("sql", QUERIES)
def test_the_rows_are_the_in_process_querys(lake: TableLake, sql: str) -> None:
    con = open_analytics(lake.root)
    try:
        want = run_query(con, sql)
    finally:
        close(con)
    with QueryProcess(_request(lake, sql)) as result:
        got = (result.names, [row for batch in result for row in batch])
    assert got == want and want[1]


def test_errors_keep_their_kind(lake: TableLake) -> None:
    with pytest.raises(duckdb.CatalogException, match="serches does not exist"):
        QueryProcess(_request(lake, "SELECT * FROM serches"))
    with pytest.raises(QueryRefusedError, match="only SELECT runs"):
        QueryProcess(_request(lake, "CREATE TABLE t AS SELECT 1"))


def test_a_process_that_dies_is_a_clear_error(lake: TableLake) -> None:
    """Killed from outside (as the kernel's OOM killer would) halfway through its rows."""
    sql = "SELECT i, repeat('x', 100) AS x FROM range(100000000) t(i)"
    with QueryProcess(_request(lake, sql, timeout_s=None)) as result:
        assert next(result)
        os.kill(result._proc.pid, signal.SIGKILL)
        with pytest.raises(QueryLimitError) as raised:
            for _ in result:
                pass
    assert "its process ended without an answer (killed by signal 9" in str(raised.value)
    assert str(raised.value).startswith("query exceeded its 1.0 GiB memory limit")


def _children(pid: int) -> list[int]:
    path = f"/proc/{pid}/task/{pid}/children"
    try:
        with open(path, encoding="ascii") as fh:
            return [int(p) for p in fh.read().split()]
    except FileNotFoundError:
        return []


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie no reaper took is not running)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def _waits_for_a_writer(pid: int) -> bool:
    """Whether a thread of ``pid`` is blocked opening a FIFO (the kernel's ``wait_for_partner``)."""
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            if (task / "wchan").read_text(encoding="ascii") == "wait_for_partner":
                return True
        except OSError:
            continue
    return False


@pytest.mark.skipif(not os.path.exists("/proc/self/wchan"), reason="reads /proc (Linux)")
def test_the_query_process_dies_with_the_command(lake: TableLake, tmp_path: Path) -> None:
    """A `query` killed with SIGKILL (it can do nothing about it) takes its query's process with
    it, even one blocked where DuckDB's interrupt never reaches (a FIFO in the lake's folder)."""
    copy = tmp_path / "lake"
    shutil.copytree(lake.root, copy)
    os.mkfifo(copy / "stuck.csv")
    sql = f"SELECT * FROM read_csv('{copy}/stuck.csv')"
    argv = ["query", "--lake", str(copy), "--timeout", "3600", sql]
    command = subprocess.Popen([sys.executable, "-m", "objsearch.cli", *argv])
    child = None
    try:
        started = time.monotonic()
        while not (children := _children(command.pid)):
            assert command.poll() is None and time.monotonic() - started < 120
            time.sleep(0.05)
        [child] = children
        while not _waits_for_a_writer(child):  # blocked opening the FIFO, past its start-up
            assert _alive(child) and time.monotonic() - started < 120
            time.sleep(0.05)
        os.kill(command.pid, signal.SIGKILL)
        command.wait()
        waited = time.monotonic()
        while _alive(child):
            assert time.monotonic() - waited < 60, "the query's process outlived its command"
            time.sleep(0.05)
    finally:
        command.kill()
        command.wait()
        if child is not None and _alive(child):
            os.kill(child, signal.SIGKILL)  # the one this test started, left by the code before
