"""Opening the lake (``events/lake/open.py``): the one place the retired per-run-folder format is
refused, naming its migration command; a lake is opened with its store or not at all; rows kept
outside any run (a ledger's) go only into a partition of their own."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events.lake import (
    LakeError,
    NoLakeError,
    TableLake,
    TableLakeError,
    TableRun,
    add_log,
    open_lake,
)

from .lake_logs import small_log


def _folder_lake(root: Path) -> Path:
    """What a per-run-folder lake looks like to the commands: a ``robot=…`` folder."""
    (root / "robot=r" / "date=2026-01-01" / "run=a").mkdir(parents=True)
    return root


@pytest.mark.parametrize("existing", [False, True])
def test_a_per_run_folder_lake_is_refused_naming_the_migration(
    tmp_path: Path, existing: bool
) -> None:
    old = _folder_lake(tmp_path / "old")
    with pytest.raises(LakeError) as caught:
        open_lake(old, store=STORE, existing=existing)
    assert not isinstance(caught.value, NoLakeError)
    assert str(caught.value) == (
        f"{old} is a per-run-folder lake (objsearch.lake/1), which this version reads only to "
        f"migrate it: run objsearch lake upgrade --lake {old}"
    )
    assert not (old / "events").exists()  # nothing was made beside it


def test_a_migrated_folder_with_runs_left_in_place_is_a_fleet_lake(tmp_path: Path) -> None:
    root = tmp_path / "lake"
    add_log(small_log(tmp_path / "log"), TableLake(root, store=STORE), robot="r")
    _folder_lake(root)  # a damaged run `lake upgrade` left beside the table
    assert [r.robot for r in open_lake(root, store=STORE, existing=True).runs()] == ["r"]


def test_where_no_lake_can_be_made_or_read(tmp_path: Path) -> None:
    with pytest.raises(NoLakeError, match=r"no lake at .*objsearch lake add LOG --lake"):
        open_lake(tmp_path / "missing", store=STORE, existing=True)
    (tmp_path / "file").write_text("x")
    with pytest.raises(LakeError, match="is a file, not a lake folder"):
        open_lake(tmp_path / "file", store=STORE)
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("x")
    with pytest.raises(LakeError, match="neither a fleet lake nor empty"):
        open_lake(tmp_path / "other", store=STORE)
    lake = open_lake(tmp_path / "new", store=STORE)  # may be made here; nothing made yet
    assert lake.store is STORE and not lake.exists()


def test_a_lake_is_opened_with_its_store_or_not_at_all(tmp_path: Path) -> None:
    # Without a store the lake once fell back to the bare schemas and silently derived no Eq. 4
    # or scene-graph table for the runs it committed.
    with pytest.raises(TypeError, match="store"):
        TableLake(tmp_path / "lake")  # type: ignore[call-arg]
    with pytest.raises(TypeError, match="store"):
        open_lake(tmp_path / "lake")  # type: ignore[call-arg]


def test_rows_outside_runs_go_only_into_a_partition_of_their_own(tmp_path: Path) -> None:
    lake = TableLake(tmp_path / "lake", store=STORE)
    info = TableRun(
        robot="r",
        date=dt.date(1970, 1, 1).isoformat(),
        run="_note:1",
        commit="",
        rows={},
        digest="",
        source="note",
        identity={"note": "1"},
        attachments={"text": "kept"},
    )
    for kind in ("_run", "detection", "derived.searches.v1"):
        with pytest.raises(TableLakeError, match="partition _<name>"):
            lake.commit_outside_runs(kind, info)
    lake.commit_outside_runs("_note", info)
    [kept] = lake.rows_outside_runs("_note")
    assert (kept.run, kept.identity, kept.attachments) == (
        "_note:1",
        {"note": "1"},
        info.attachments,
    )
    assert kept.commit  # the lake's token
    assert lake.runs() == [] and {f.kind for f in lake.data_files()} == {"_note"}
    lake.check_runs()  # not a run: the runs' records still add up
