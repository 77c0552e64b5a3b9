"""Ingest as a command: atomic commits, parallel workers, clear errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.cli import main
from objsearch.cli_bags import BAG_FORMATS
from objsearch.pipeline.bags.formats import BagFormat
from objsearch.pipeline.bags.ingest import ingest
from objsearch.pipeline.bags.lake import FleetBagLake
from objsearch.pipeline.bags.ledger import bag_records

from .bag_fixtures import Recorded


def test_a_failed_commit_leaves_nothing(
    recorded: Recorded, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import pyarrow.parquet as pq

    def disk_full(*args: object, **kwargs: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pq, "write_table", disk_full)
    [result] = ingest([recorded.bag], tmp_path / "lake")
    assert result.error is not None and "No space left" in result.error
    assert not list((tmp_path / "lake").rglob("*.parquet"))
    fleet = FleetBagLake(tmp_path / "lake").lake
    assert fleet.runs() == [] and fleet.data_files() == [] and bag_records(fleet) == {}
    monkeypatch.undo()
    [again] = ingest([recorded.bag], tmp_path / "lake")  # the next try commits it whole
    assert again.error is None and again.committed > 0


def test_two_workers_give_the_same_lake_as_one(recorded: Recorded, tmp_path: Path) -> None:
    import shutil

    from objsearch.pipeline.bags.formats import storage_files

    # A second, different bag: the same recording cut at 80 % (read by the salvage scanner).
    cut = tmp_path / ("cut.bag" if recorded.bag.is_file() else "cut")
    if recorded.bag.is_dir():
        shutil.copytree(recorded.bag, cut)
    else:
        shutil.copy(recorded.bag, cut)
    data = storage_files(cut)[0]
    with data.open("r+b") as fh:
        fh.truncate(int(data.stat().st_size * 0.8))
    bags = [recorded.bag, cut]
    one = ingest(bags, tmp_path / "one", workers=1)
    two = ingest(bags, tmp_path / "two", workers=2)
    # One recording session: the cut adds nothing to the whole (or the whole completes the
    # cut, if the cut is committed first); either way the lake is the same.
    assert all(r.error is None for r in two)
    assert sum(r.committed for r in one) == sum(r.committed for r in two) > 0
    assert [r.report for r in one] == [r.report for r in two]
    assert list(FleetBagLake(tmp_path / "one").events()) == list(
        FleetBagLake(tmp_path / "two").events()
    )


def test_cli_ingest_reports_and_is_idempotent(
    recorded: Recorded, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lake = str(tmp_path / "lake")
    assert main(["ingest", str(recorded.bag), "--lake", lake, "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "/objsearch/events" in out and "time range" in out and "committed" in out
    assert main(["ingest", str(recorded.bag), "--lake", lake]) == 0
    assert "already in the lake" in capsys.readouterr().out


def test_cli_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["ingest", str(tmp_path / "nope.bag"), "--lake", str(tmp_path / "l")]) == 2
    assert "no such file or folder" in capsys.readouterr().err
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"\x00" * 100)
    assert main(["ingest", str(junk), "--lake", str(tmp_path / "l")]) == 2
    assert "not a ROS bag" in capsys.readouterr().err
    assert main(["record", "--out", str(tmp_path / "x.bag"), "--bag-format", "ros3"]) == 2
    assert "invalid choice: 'ros3'" in capsys.readouterr().err
    assert tuple(f.value for f in BagFormat) == BAG_FORMATS  # the choices are every format
    assert main(["record", "--out", str(tmp_path / "x"), "--bag-format", "ros1"]) == 2
    assert "named *.bag" in capsys.readouterr().err
