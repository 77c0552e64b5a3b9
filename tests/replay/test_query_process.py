"""An analyst's query in a process of its own (:mod:`objsearch.replay.query_process`): the same
rows and errors as in-process, and a process that dies is said, not a hang or a traceback."""

from __future__ import annotations

import os
import signal

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
