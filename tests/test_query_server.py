"""devtools/query_server.py: ``objsearch query`` with its process forked from a warm one answers
as with a fresh interpreter, byte for byte and exit code for exit code, and the lake batteries'
commands start no interpreter for their queries."""

from __future__ import annotations

import os
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from devtools import query_server
from devtools.lake_battery import build_lake, every_row_sql, run_cli


@pytest.fixture(scope="module")
def lake(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    yield build_lake(tmp_path_factory.mktemp("query-server"))
    query_server.close_server()


#: name: (the words after ``query --lake LAKE``, exit code, what its output holds)
QUERIES: dict[str, tuple[tuple[str, ...], int, str]] = {
    "every row of every view": (("--format", "json", every_row_sql()), 0, '"view": "searches"'),
    "a table of rows": (("SELECT run, target FROM searches ORDER BY ALL",), 0, "(3 rows)"),
    "an unknown table": (("SELECT * FROM nope",), 2, "Table with name nope does not exist"),
    "a refused statement": (("COPY (SELECT 1) TO 'out.csv'",), 2, "read-only"),
    # DuckDB interrupted at the limit by the process's own timer
    "the time limit": (
        (
            "--timeout",
            "1",
            "SELECT sum(hash(a.range * b.range)) FROM range(100000) a, range(100000) b",
        ),
        2,
        "exceeded its 1 s time limit",
    ),
    "the memory limit": (
        ("--memory-limit", "64MB", "SELECT repeat('x', 300000000) AS s"),
        2,
        "memory limit",
    ),
}


@pytest.mark.parametrize(("words", "code", "said"), QUERIES.values(), ids=QUERIES.keys())
def test_a_forked_query_answers_as_a_fresh_process(
    lake: Path,
    words: tuple[str, ...],
    code: int,
    said: str,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(tmp_path)  # a COPY let through would write here
    argv = ["query", "--lake", str(lake), *words]
    fresh = run_cli(argv, fork_queries=False)
    assert fresh.code == code and said in fresh.stdout + fresh.stderr, fresh
    forked = run_cli(argv)
    assert (forked.code, forked.stdout, forked.stderr) == (fresh.code, fresh.stdout, fresh.stderr)
    assert list(tmp_path.iterdir()) == []


def test_the_batteries_start_no_interpreter_for_a_query(
    lake: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    started: list[list[str]] = []
    popen = subprocess.Popen

    def counted(args: Any, *rest: Any, **kwargs: Any) -> Any:
        started.append(list(args))
        return popen(args, *rest, **kwargs)

    monkeypatch.setattr(subprocess, "Popen", counted)
    query = ["query", "--lake", str(lake), "SELECT count(*) FROM searches"]
    assert run_cli(query).code == 0
    assert [a for a in started if a[-1] == query_server.QUERY_MODULE] == []
    assert run_cli(query, fork_queries=False).code == 0  # the count sees a fresh one
    assert [a[-2:] for a in started] == [["-m", query_server.QUERY_MODULE]]
    assert subprocess.Popen is counted  # put back as it was


def test_the_querys_process_is_the_servers_child_and_killable(lake: Path) -> None:
    server = query_server.QueryServer()
    try:
        env = os.environ | {"OBJSEARCH_QUERY_PARENT": str(os.getpid())}
        proc = query_server.Forked(server, ["python", "-m", query_server.QUERY_MODULE], env)
        with pytest.raises(RuntimeError, match="one query at a time"):
            query_server.Forked(server, ["python", "-m", query_server.QUERY_MODULE], env)
        status = Path(f"/proc/{proc.pid}/status").read_text(encoding="ascii")
        assert f"PPid:\t{server._proc.pid}\n" in status
        assert proc.poll() is None  # it waits for its request on stdin
        with pytest.raises(subprocess.TimeoutExpired):
            proc.wait(timeout=0.1)
        proc.kill()
        assert proc.wait(timeout=10) == -9
        proc.stdin.close()
        proc.stdout.close()
    finally:
        server.close()


def test_a_bug_in_the_querys_process_ends_it_with_its_traceback_on_the_commands_stderr(
    tmp_path: Path,
) -> None:
    """As a fresh process inherits the command's stderr, so does a forked one: the stderr the
    command has when it starts the query (not when the server started)."""
    server = query_server.QueryServer()
    saved = os.dup(2)
    try:
        with (tmp_path / "stderr").open("wb") as now:
            os.dup2(now.fileno(), 2)
            env = os.environ | {"OBJSEARCH_QUERY_PARENT": str(os.getpid())}
            proc = query_server.Forked(server, ["python", "-m", query_server.QUERY_MODULE], env)
            os.dup2(saved, 2)
        proc.stdin.write(b"not a request")  # main cannot read it: a bug, as a fresh process says
        proc.stdin.close()
        assert proc.stdout.read() == b""
        proc.stdout.close()
        assert proc.wait(timeout=60) == 1
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        server.close()
    said = (tmp_path / "stderr").read_text()
    assert "Traceback" in said and "JSONDecodeError" in said, said
