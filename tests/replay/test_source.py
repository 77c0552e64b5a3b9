"""Replay, audit and ``where`` read a run from a fleet lake — a folder or a bucket — as they read
the log it came from; a run whose files do not read back as committed is an error, never a
shorter replay."""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from objsearch.agent.catalogue import STORE
from objsearch.cli import main
from objsearch.events.lake import TableLake, TableLakeError, add_log
from objsearch.replay.source import open_events

RUN = "targets"


def _answers(capsys: pytest.CaptureFixture[str], where: str, *run: str) -> dict[str, object]:
    """What replay, audit and where print for the log or lake at ``where``."""
    capsys.readouterr()
    out: dict[str, object] = {}
    assert main(["replay", where, *run, "--format", "json", "--all", "--no-progress"]) == 0
    out["replay"] = json.loads(capsys.readouterr().out)
    assert main(["audit", where, *run, "--format", "json", "--no-progress"]) == 0
    out["audit"] = json.loads(capsys.readouterr().out)
    # A fixed time of the week: the default, now, is the local clock, which moves between the
    # log's call and the lake's (once the two answers differed in `where` alone).
    assert main(["where", "Cup", where, *run, "--at", "mon 09:00", "--format", "json"]) == 0
    out["where"] = json.loads(capsys.readouterr().out)
    return out


def _fleet(root: Path | str, log: Path) -> TableLake:
    lake = TableLake(root, store=STORE)
    add_log(log, lake, robot="sim")
    return lake


def test_a_fleet_folder_lake_answers_as_the_log_did(
    tmp_path: Path, logs: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    _fleet(tmp_path / "fleet", logs[RUN])
    from_log = _answers(capsys, str(logs[RUN]))
    from_lake = _answers(capsys, str(tmp_path / "fleet"), "--run", RUN)
    assert from_lake == from_log
    assert from_log["replay"]  # there were decisions to compare


def test_a_run_of_a_bucket_reads_as_the_log(bucket: str, logs: dict[str, Path]) -> None:
    _fleet(bucket, logs[RUN])
    events, name = open_events(bucket, run=RUN)
    assert name == f"{bucket} (sim/{RUN})"
    logged, _ = open_events(logs[RUN])
    assert list(events) == list(logged)


@pytest.mark.parametrize("change", ["one row fewer", "a later time"])
def test_a_run_whose_file_was_altered_is_refused(
    tmp_path: Path, logs: dict[str, Path], capsys: pytest.CaptureFixture[str], change: str
) -> None:
    lake = _fleet(tmp_path / "fleet", logs[RUN])
    # The detections' file rewritten: valid Parquet of the same schema (so no reader's own check
    # fails), but not what the commit recorded — fewer rows, or as many with other values.
    (detections,) = [
        Path(lake.uri) / f.path for f in lake.data_files() if "type=detection" in f.path
    ]
    table = pq.read_table(detections)
    if change == "one row fewer":
        table = table.slice(1)
    else:
        at = table.schema.get_field_index("time_ns")
        table = table.set_column(at, "time_ns", pc.add(table.column(at), 1))
    pq.write_table(table, detections)
    with pytest.raises(TableLakeError, match=r"damaged: its rows do not read back as committed"):
        open_events(tmp_path / "fleet", run=RUN)
    capsys.readouterr()
    assert main(["replay", str(tmp_path / "fleet"), "--run", RUN, "--no-progress"]) == 2
    assert "is damaged" in capsys.readouterr().err


def test_a_run_whose_file_is_gone_is_refused(tmp_path: Path, logs: dict[str, Path]) -> None:
    lake = _fleet(tmp_path / "fleet", logs[RUN])
    (Path(lake.uri) / lake.data_files()[0].path).unlink()
    with pytest.raises(TableLakeError, match=r"could not be read|damaged"):
        open_events(tmp_path / "fleet", run=RUN)


def test_an_address_that_is_no_bucket_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", "s3:///lake", "--run", RUN]) == 2
    assert "no bucket" in capsys.readouterr().err
    assert main(["where", "Cup", "gs://b/lake"]) == 2
    assert "only s3://" in capsys.readouterr().err


def test_a_damaged_commit_of_the_tables_log_is_a_clear_error(
    tmp_path: Path, logs: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    # Found by objsearch.fleet_battery: delta-rs's error came out as a traceback.
    lake = _fleet(tmp_path / "fleet", logs[RUN])
    (commit,) = sorted(Path(lake.uri, "_delta_log").glob("*.json"))[-1:]
    commit.write_bytes(commit.read_bytes()[: len(commit.read_bytes()) // 2])
    capsys.readouterr()
    sql = "SELECT count(*) FROM events"
    assert main(["query", "--lake", str(tmp_path / "fleet"), sql]) == 2
    assert "the table's log of the fleet lake" in capsys.readouterr().err
    assert main(["replay", str(tmp_path / "fleet"), "--run", RUN, "--no-progress"]) == 2
    assert "is damaged and cannot be read" in capsys.readouterr().err
