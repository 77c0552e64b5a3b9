"""The per-run-folder lake (``objsearch.lake/1``) is read only to migrate it: ``objsearch lake
upgrade`` copies its healthy runs into the fleet lake, which then answers as the old lake did;
a damaged run is named and left in place; every other command refuses such a lake.

The old lake is ``fixtures/lake-v1/lake``, written by the last code that wrote the format, with
what that code's views answered beside it (``fixtures/README.md``): committed bytes, so the test
holds the migration to lakes as they are on disk, not to a writer kept alive for the test.
"""

from __future__ import annotations

import datetime as dt
import json
import shutil
from pathlib import Path
from typing import Any

import pytest

from objsearch.cli import main
from objsearch.events.lake import is_table_lake
from objsearch.events.lake.folder_v1 import is_folder_lake
from objsearch.events.sql_limits import close
from objsearch.pipeline.bags.lake import FleetBagLake
from objsearch.pipeline.bags.ledger import bag_records
from objsearch.replay.analytics import open_analytics, run_query

FIXTURE = Path(__file__).parent / "fixtures" / "lake-v1"
SIM_RUN = Path("robot=sim") / "date=2026-01-01" / "run=robot"
SMALL_RUN = Path("robot=r2d2") / "date=2023-11-14" / "run=run-a"


def old_lake(tmp_path: Path) -> Path:
    lake = tmp_path / "lake"
    shutil.copytree(FIXTURE / "lake", lake)
    return lake


def plain(value: Any) -> Any:
    """A value as the fixture's answers hold it (JSON: dates as ISO text, tuples as lists)."""
    if isinstance(value, dt.date | dt.datetime):
        return value.isoformat()
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    return value


def test_upgrade_copies_every_run_and_the_fleet_lake_answers_as_the_old_one_did(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lake = old_lake(tmp_path)
    assert main(["lake", "upgrade", "--lake", str(lake), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "2 run(s) copied into the fleet table (2 in all); their folders removed" in out
    assert is_table_lake(lake) and not is_folder_lake(lake)
    assert not list(lake.glob("robot=*"))
    answers = json.loads((FIXTURE / "answers.json").read_text())
    for sql, want in answers.items():
        # as `objsearch query` opens it (only the views the query reads) and as a notebook does
        for for_sql in (sql, None):
            con = open_analytics(lake, for_sql=for_sql)
            try:
                assert plain(run_query(con, sql)[1]) == want, sql
            finally:
                close(con)
    # Again: nothing left to migrate.
    assert main(["lake", "upgrade", "--lake", str(lake)]) == 0
    assert "already a fleet lake" in capsys.readouterr().out


def test_a_damaged_run_is_named_not_copied_and_left_in_place(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lake = old_lake(tmp_path)
    damaged = lake / SIM_RUN / "detection.parquet"
    data = bytearray(damaged.read_bytes())
    data[len(data) // 2] ^= 0x10  # same size: only its SHA-256 tells
    damaged.write_bytes(bytes(data))
    assert main(["lake", "upgrade", "--lake", str(lake), "--no-progress"]) == 2
    captured = capsys.readouterr()
    assert (
        f"objsearch: warning: damaged run not copied, left in place: {lake / SIM_RUN}: "
        "detection.parquet" in captured.err
    )
    assert "1 run(s) copied" in captured.out and "1 damaged run(s) left in place" in captured.out
    assert damaged.read_bytes() == bytes(data)  # the damaged run is as it was
    assert not (lake / SMALL_RUN).exists()  # the healthy one is in the table
    assert main(["lake", "ls", "--lake", str(lake), "--format", "csv"]) == 0
    captured = capsys.readouterr()
    rows = captured.out.splitlines()[1:]
    assert [r.split(",")[:3] for r in rows] == [["r2d2", "2023-11-14", "run-a"]]
    assert "holds 1 run folder(s) of the old per-run-folder format" in captured.err
    assert str(lake / SIM_RUN) in captured.err


def test_upgrade_into_another_lake_leaves_the_folder_lake_as_it_is(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lake = old_lake(tmp_path)
    before = sorted(p.relative_to(lake) for p in lake.rglob("*"))
    fleet = tmp_path / "fleet"
    assert main(["lake", "upgrade", "--lake", str(lake), "--into", str(fleet)]) == 0
    assert "2 run(s) copied" in capsys.readouterr().out
    assert sorted(p.relative_to(lake) for p in lake.rglob("*")) == before
    assert is_table_lake(fleet)


def test_upgrade_of_what_is_no_folder_lake(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "file").write_text("x")
    assert main(["lake", "upgrade", "--lake", str(tmp_path / "file")]) == 2
    assert "is a file, not a folder" in capsys.readouterr().err  # the option's type says it
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("x")
    assert main(["lake", "upgrade", "--lake", str(tmp_path / "other")]) == 2
    assert "holds no per-run-folder lake to upgrade" in capsys.readouterr().err
    assert main(["lake", "upgrade", "--lake", str(tmp_path / "new")]) == 0
    assert "created an empty fleet lake" in capsys.readouterr().out
    assert is_table_lake(tmp_path / "new")


def test_the_reports_of_bags_that_made_no_run_are_copied(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # As the old ingest kept a bag that made no run: its report in _bags/, and nowhere else.
    lake = old_lake(tmp_path)
    bag_id = "ab" * 32
    doc = {"bag_id": bag_id, "robot": None, "run": None, "events": 0, "report": {"lost": 3}}
    (lake / "_bags").mkdir()
    (lake / "_bags" / f"{bag_id}.json").write_text(json.dumps(doc))
    assert main(["lake", "upgrade", "--lake", str(lake)]) == 0
    capsys.readouterr()
    assert json.loads(bag_records(FleetBagLake(lake).lake)[bag_id]) == doc


def _refusals(lake: Path, log: Path) -> list[list[str]]:
    where = str(lake)
    return [
        ["query", "--lake", where, "SELECT 1"],
        ["lake", "add", str(log), "--robot", "r", "--lake", where],
        ["lake", "ls", "--lake", where],
        ["lake", "verify", where],
        ["lake", "compact", "--lake", where],
        ["replay", where],
        ["audit", where],
        ["where", "Apple", where],
        ["liveview", where, "--mcap", str(lake.parent / "out.mcap")],
        ["ingest", str(log / "meta.json"), "--lake", where, "--no-progress"],
    ]


@pytest.mark.parametrize("command", range(len(_refusals(Path("l"), Path("g")))))
def test_every_other_command_refuses_a_folder_lake(
    tmp_path: Path, command: int, capsys: pytest.CaptureFixture[str]
) -> None:
    lake = old_lake(tmp_path)
    log = Path(__file__).parent / "fixtures" / "v1-log"
    before = sorted(p.relative_to(lake) for p in lake.rglob("*"))
    argv = _refusals(lake, log)[command]
    assert main(argv) == 2, argv
    assert capsys.readouterr().err.endswith(
        f"objsearch: error: {lake} is a per-run-folder lake (objsearch.lake/1), which this "
        f"version reads only to migrate it: run objsearch lake upgrade --lake {lake}\n"
    )
    assert sorted(p.relative_to(lake) for p in lake.rglob("*")) == before
