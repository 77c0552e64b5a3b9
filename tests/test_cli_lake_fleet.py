"""``objsearch lake upgrade --to fleet`` / ``add`` / ``ls`` / ``verify`` / ``compact`` and
``objsearch query`` over the fleet lake, in process."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.cli import main
from objsearch.events import EventLog
from objsearch.events.lake import Lake, compact_log

EVENTS = 4


def small_log(directory: Path, *, stream: str) -> Path:
    with EventLog.open(
        directory, stream, wall_clock=lambda: 1_700_000_000_000_000_000, store=STORE
    ) as log:
        for i in range(EVENTS):
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=i)
    return directory


def test_upgrade_add_ls_verify_compact_query(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lake = str(tmp_path / "lake")
    compact_log(small_log(tmp_path / "a", stream="a"), Lake(lake, store=STORE), robot="r")
    assert main(["lake", "upgrade", "--to", "fleet", "--lake", lake]) == 0
    assert "1 run(s) copied" in capsys.readouterr().out
    assert not list(Path(lake).glob("robot=*"))
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
    assert main(["lake", "upgrade", "--to", "fleet", "--lake", lake]) == 0
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


def test_compact_refuses_a_per_run_folder_lake(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    compact_log(
        small_log(tmp_path / "a", stream="a"), Lake(tmp_path / "lake", store=STORE), robot="r"
    )
    assert main(["lake", "compact", "--lake", str(tmp_path / "lake")]) == 2
    assert "upgrade --to fleet" in capsys.readouterr().err
