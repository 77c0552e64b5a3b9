"""``objsearch lake add`` / ``ls`` / ``verify`` / ``compact`` and ``objsearch query`` over the
fleet lake (the default: a missing ``--lake`` folder becomes one), in process. The migration of a
per-run-folder lake and the other commands' refusal of one: tests/events/test_lake_folder_v1.py."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.cli import main
from objsearch.events import EventLog
from objsearch.events.lake import is_table_lake

EVENTS = 4


def small_log(directory: Path, *, stream: str) -> Path:
    with EventLog.open(
        directory, stream, wall_clock=lambda: 1_700_000_000_000_000_000, store=STORE
    ) as log:
        for i in range(EVENTS):
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=i)
    return directory


def test_add_ls_verify_compact_query(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    lake = str(tmp_path / "lake")
    log_a = small_log(tmp_path / "a", stream="a")
    assert main(["lake", "add", str(log_a), "--robot", "r", "--lake", lake]) == 0
    assert is_table_lake(lake)
    log_b = small_log(tmp_path / "b", stream="b")
    assert main(["lake", "add", str(log_b), "--robot", "r", "--lake", lake]) == 0
    assert main(["lake", "add", str(log_b), "--robot", "r", "--lake", lake]) == 0  # no-op
    capsys.readouterr()
    assert main(["lake", "ls", "--lake", lake, "--format", "csv"]) == 0
    n = EVENTS
    assert capsys.readouterr().out.splitlines()[1:] == [
        f"r,2023-11-14,a,{n},event log {(tmp_path / 'a').resolve()}",
        f"r,2023-11-14,b,{n},event log {(tmp_path / 'b').resolve()}",
    ]
    assert main(["lake", "verify", lake]) == 0
    assert main(["lake", "compact", "--lake", lake, "--keep-hours", "0"]) == 0
    capsys.readouterr()
    sql = "SELECT run, count(*) AS n FROM events GROUP BY 1 ORDER BY 1"
    assert main(["query", "--lake", lake, "--format", "csv", sql]) == 0
    assert capsys.readouterr().out.splitlines() == ["run,n", f"a,{n}", f"b,{n}"]


@pytest.mark.parametrize(
    "sql",
    ["COPY (SELECT 1) TO 'OUT'", "SELECT * FROM read_csv('/etc/passwd')", "SET memory_limit='8GB'"],
)
def test_the_sandbox_holds_over_the_fleet_lake(
    tmp_path: Path, sql: str, capsys: pytest.CaptureFixture[str]
) -> None:
    lake = str(tmp_path / "lake")
    assert (
        main(
            [
                "lake",
                "add",
                str(small_log(tmp_path / "a", stream="a")),
                "--robot",
                "r",
                "--lake",
                lake,
            ]
        )
        == 0
    )
    capsys.readouterr()
    out = tmp_path / "x.csv"
    assert main(["query", "--lake", lake, sql.replace("OUT", str(out))]) == 2
    assert "objsearch: error:" in capsys.readouterr().err
    assert not out.exists()


def test_a_folder_that_is_neither_a_fleet_lake_nor_empty_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "lake"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine\n")
    log = str(small_log(tmp_path / "a", stream="a"))
    assert main(["lake", "add", log, "--robot", "r", "--lake", str(folder)]) == 2
    assert (
        f"objsearch: error: {folder} is neither a fleet lake nor empty" in capsys.readouterr().err
    )
    assert [p.name for p in folder.iterdir()] == ["notes.txt"]
    assert main(["lake", "ls", "--lake", str(tmp_path / "missing")]) == 2
    assert "no lake at" in capsys.readouterr().err
    assert not (tmp_path / "missing").exists()
