"""The fleet lake's runs' records against its table (issue 43, items 2 and 7): a commit file of
the table's log edited (an ``add`` removed) or the newest one deleted is refused by every read
path and named by ``lake verify``, never answered without the rows; a damaged ``_run`` file
costs its runs, not the lake, and nothing ends in a traceback. Every lake here is made by the
real CLI (``objsearch search`` then ``objsearch lake add``, :func:`build_lake`)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from devtools.killtest import tree
from devtools.lake_battery import build_lake, run_cli
from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake
from objsearch.events.lake.schema import RUN_TYPE, TABLE_DIR

SQL = "SELECT run, count(*) AS n FROM detection GROUP BY run ORDER BY run"


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The three-run lake and a fourth run's log, for ``lake add``."""
    root = tmp_path_factory.mktemp("bookkeeping")
    lake = build_lake(root)
    log = root / "log-phone"
    argv = ["search", "Phone", "--start", "kitchen-1", "--log", str(log), "--format", "json"]
    assert run_cli(argv).code == 0
    return lake, log


def _copy(built: tuple[Path, Path], where: Path) -> Path:
    shutil.copytree(built[0], where)
    return where


def _commit(lake: Path, version: int) -> Path:
    return lake / TABLE_DIR / "_delta_log" / f"{version:020d}.json"


def _remove_add(lake: Path, version: int, kind: str) -> None:
    path = _commit(lake, version)
    lines = path.read_text().splitlines(keepends=True)
    kept = [line for line in lines if f'"path":"type={kind}/' not in line]
    assert len(kept) == len(lines) - 1
    path.write_text("".join(kept))


def _refused(argv: list[str], *words: str) -> str:
    outcome = run_cli(argv)
    assert outcome.code == 2, (argv, outcome)
    assert "Traceback" not in outcome.stderr
    assert "objsearch: error: " in outcome.stderr
    for word in words:
        assert word in outcome.stderr, (word, outcome.stderr)
    return outcome.stdout


@pytest.mark.parametrize(
    ("kind", "said"),
    [
        ("detection", "type=detection holds 51 rows, the runs recorded 110"),
        # the run's record gone: its rows are rows no record names
        (RUN_TYPE, "row(s) no run's record names"),
        ("derived.searches.v4", "type=derived.searches.v4 holds 2 rows, the runs recorded 3"),
    ],
)
def test_an_add_removed_from_a_commit_is_refused_by_every_read_path_and_named_by_verify(
    built: tuple[Path, Path], tmp_path: Path, kind: str, said: str
) -> None:
    lake = _copy(built, tmp_path / "lake")
    # commit 2 is run cup's (commit 1 apple's, 3 bowl's)
    _remove_add(lake, 2, kind)
    before = tree(lake)
    _refused(["query", "--lake", str(lake), SQL], said, "lake verify")
    _refused(["lake", "ls", "--lake", str(lake)], said)
    found = json.loads(_refused(["lake", "verify", str(lake), "--format", "json", "--no-progress"]))
    assert found["damaged"] == []
    assert [r["run"] for r in found["runs_damaged"]] == ["r1/cup"]
    assert tree(lake) == before  # no reader changed the lake
    # compaction (and its vacuum) would make the loss permanent: refused, the lake as it was
    _refused(["lake", "compact", "--lake", str(lake), "--keep-hours", "0"], said)
    assert tree(lake) == before
    log = built[1]
    _refused(["lake", "add", str(log), "--robot", "r1", "--lake", str(lake), "--no-progress"])
    assert tree(lake) == before


def test_the_newest_commit_file_deleted_is_refused_not_answered_without_its_run(
    built: tuple[Path, Path], tmp_path: Path
) -> None:
    lake = _copy(built, tmp_path / "lake")
    _commit(lake, 3).unlink()  # run bowl's commit
    _refused(["query", "--lake", str(lake), SQL], "version 3", "missing")
    _refused(["lake", "ls", "--lake", str(lake)], "version 3")
    found = json.loads(_refused(["lake", "verify", str(lake), "--format", "json", "--no-progress"]))
    assert [r["run"] for r in found["runs_damaged"]] == ["_delta_log"]
    before = tree(lake)
    _refused(["lake", "compact", "--lake", str(lake), "--keep-hours", "0"], "version 3")
    assert tree(lake) == before  # bowl's files are still there to restore the commit from


def test_a_compacted_lake_missing_its_newest_commit_file_refuses_an_add_clearly(
    built: tuple[Path, Path], tmp_path: Path
) -> None:
    lake = _copy(built, tmp_path / "lake")
    assert run_cli(["lake", "compact", "--lake", str(lake)]).code == 0
    version = int(TableLake(lake, store=STORE).table().version())
    intact = run_cli(["query", "--lake", str(lake), "--format", "json", SQL])
    _commit(lake, version).unlink()  # read from its checkpoint, but no commit can follow
    # was: DeltaError: Invalid table version (a traceback)
    log = built[1]
    _refused(
        ["lake", "add", str(log), "--robot", "r1", "--lake", str(lake), "--no-progress"],
        f"{version:020d}.json",
        "missing",
    )
    # the table itself is whole (its checkpoint): readers answer as before
    again = run_cli(["query", "--lake", str(lake), "--format", "json", SQL])
    assert (again.code, again.stdout) == (0, intact.stdout)


@pytest.mark.parametrize("damage", ["deleted", "garbage"])
def test_a_damaged_run_file_costs_its_runs_not_the_lake(
    built: tuple[Path, Path], tmp_path: Path, damage: str
) -> None:
    lake = _copy(built, tmp_path / "lake")
    (apple,) = [
        lake / TABLE_DIR / f.path
        for f in TableLake(lake, store=STORE).data_files()
        if f.kind == RUN_TYPE and f.path in _commit(lake, 1).read_text()
    ]
    rel = str(apple.relative_to(lake / TABLE_DIR))
    if damage == "deleted":
        apple.unlink()
    else:
        apple.write_bytes(b"garbage")
    # lake ls lists the other runs, then names the file and what is wrong (was: a traceback)
    listed = _refused(["lake", "ls", "--lake", str(lake), "--format", "json"], rel)
    assert [r["run"] for r in json.loads(listed)] == ["bowl", "cup"]
    # verify reports and goes on (was: a raw thrift error)
    found = json.loads(_refused(["lake", "verify", str(lake), "--format", "json", "--no-progress"]))
    assert [d["file"] for d in found["damaged"]] == [rel]
    assert found["runs"] == 2
    # a new run is added (was: blocked by the one file)
    log = built[1]
    added = run_cli(
        ["lake", "add", str(log), "--robot", "r1", "--lake", str(lake), "--no-progress"]
    )
    assert added.code == 0, added.stderr
    assert rel in added.stderr  # with a warning naming the file
    # adding apple's log again cannot be told from the table: a clear error naming the file
    _refused(
        [
            "lake",
            "add",
            str(built[0].parent / "log-apple"),
            "--robot",
            "r1",
            "--run",
            "apple",
            "--lake",
            str(lake),
            "--no-progress",
        ],
        rel,
    )


def test_a_commit_cut_to_its_commit_info_or_copied_as_a_later_version_is_refused(
    built: tuple[Path, Path], tmp_path: Path
) -> None:
    # found by the lake-bookkeeping battery: both changed the answer with the counts agreeing
    # (a whole run gone with its record; a run there twice with its record)
    cut = _copy(built, tmp_path / "cut")
    path = _commit(cut, 1)
    path.write_text(path.read_text().splitlines(keepends=True)[0])  # run apple's commitInfo
    _refused(["query", "--lake", str(cut), SQL], f"{path.name} holds no action")
    _refused(["lake", "compact", "--lake", str(cut), "--keep-hours", "0"], "holds no action")
    copied = _copy(built, tmp_path / "copied")
    assert run_cli(["lake", "compact", "--lake", str(copied), "--keep-hours", "1"]).code == 0
    latest = int(TableLake(copied, store=STORE).table().version())
    shutil.copyfile(_commit(copied, 1), _commit(copied, latest + 1))  # apple's old files again
    _refused(["query", "--lake", str(copied), SQL], "run r1/apple is recorded more than once")
    _refused(["lake", "ls", "--lake", str(copied)], "run r1/apple is recorded more than once")


def test_a_compaction_with_its_vacuum_leaves_a_lake_every_read_path_takes(
    built: tuple[Path, Path], tmp_path: Path
) -> None:
    # its vacuum commits hold only a commitInfo (VACUUM START / END): no run was taken out
    lake = _copy(built, tmp_path / "lake")
    intact = run_cli(["query", "--lake", str(lake), "--format", "json", SQL])
    assert run_cli(["lake", "compact", "--lake", str(lake), "--keep-hours", "0"]).code == 0
    again = run_cli(["query", "--lake", str(lake), "--format", "json", SQL])
    assert (again.code, again.stdout) == (0, intact.stdout), again.stderr
    verify = run_cli(["lake", "verify", str(lake), "--no-progress"])
    assert verify.code == 0, verify.stdout + verify.stderr
    added = run_cli(
        ["lake", "add", str(built[1]), "--robot", "r1", "--lake", str(lake), "--no-progress"]
    )
    assert added.code == 0, added.stderr
