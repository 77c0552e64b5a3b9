"""The fleet lake's files read from its table's log without delta-rs
(``events/lake/log_listing.py``): the same files, sizes, rows, statistics and transactions as
delta-rs reads, a log it does not know left to delta-rs, damage refused, and ``where`` /
``replay`` from a lake run with no delta-rs loaded."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pyarrow as pa
import pytest

from devtools.lake_battery import build_lake, run_cli
from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake, TableLakeError
from objsearch.events.lake.log_listing import LogListing, read_listing
from objsearch.events.lake.schema import TABLE_DIR


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A lake of three runs (apple, cup, bowl), one commit each after the table's creation."""
    return build_lake(tmp_path_factory.mktemp("listing"))


def _copy(built: Path, where: Path) -> Path:
    shutil.copytree(built, where)
    return where


def _commit(lake: Path, version: int) -> Path:
    return lake / TABLE_DIR / "_delta_log" / f"{version:020d}.json"


def _listing(lake: Path) -> LogListing | None:
    return read_listing(str(lake.absolute() / TABLE_DIR), lake)


def _same_as_delta_rs(lake: Path) -> None:
    listing = _listing(lake)
    assert listing is not None
    table = TableLake(lake, store=STORE).table()  # delta-rs
    ours = listing.get_add_actions().sort_by("path")
    theirs = pa.table(table.get_add_actions(flatten=True)).select(ours.column_names)
    assert ours.cast(theirs.schema).equals(theirs.sort_by("path"))
    assert listing.version() == table.version()
    assert sorted(listing.file_uris()) == sorted(table.file_uris())
    kinds = [("type", "in", ["detection", "_run"])]
    assert sorted(listing.file_uris(kinds)) == sorted(table.file_uris(file_pruning_predicate=kinds))
    apps = set()
    for path in (lake / TABLE_DIR / "_delta_log").glob("*.json"):
        for line in path.read_text().splitlines():
            if line.startswith('{"txn"'):
                apps.add(json.loads(line)["txn"]["appId"])
    assert apps
    for app in [*sorted(apps), "no-such-app"]:
        assert listing.transaction_version(app) == table.transaction_version(app), app


def test_the_log_reads_as_delta_rs_reads_it(built: Path, tmp_path: Path) -> None:
    _same_as_delta_rs(built)
    # a run removed: its files' ``remove`` actions applied
    lake = _copy(built, tmp_path / "lake")
    assert TableLake(lake, store=STORE).remove_run("r1", "cup")
    _same_as_delta_rs(lake)
    again = run_cli(["where", "Apple", str(lake), "--run", "apple", "--format", "json"])
    assert again.code == 0, again.stderr


def test_a_log_it_does_not_read_is_left_to_delta_rs(built: Path, tmp_path: Path) -> None:
    lake = _copy(built, tmp_path / "lake")
    answer = run_cli(["where", "Apple", str(lake), "--run", "apple", "--format", "json"])
    assert run_cli(["lake", "compact", "--lake", str(lake)]).code == 0  # checkpoints the log
    assert _listing(lake) is None
    listing = TableLake(lake, store=STORE).listing()
    assert not isinstance(listing, LogListing)
    again = run_cli(["where", "Apple", str(lake), "--run", "apple", "--format", "json"])
    assert (again.code, again.stdout) == (answer.code, answer.stdout)
    # an action it does not apply (a deletion vector): delta-rs's
    other = _copy(built, tmp_path / "dv")
    path = _commit(other, 2)
    lines = path.read_text().splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith('{"add"'))
    add = json.loads(lines[at])
    add["add"]["deletionVector"] = {"storageType": "u", "pathOrInlineDv": "x", "sizeInBytes": 1}
    lines[at] = json.dumps(add)
    path.write_text("\n".join(lines) + "\n")
    assert _listing(other) is None


def _garble(path: Path) -> None:
    path.write_text(path.read_text().replace('"add"', '"add', 1))


def _cut(path: Path) -> None:
    text = path.read_text()
    path.write_text(text[: len(text) // 2])


@pytest.mark.parametrize(
    ("damage", "said"),
    [
        (_garble, "00000000000000000002.json line"),
        (_cut, "00000000000000000002.json line"),
        (Path.unlink, "version 2 missing"),
    ],
    ids=["garbled", "cut", "deleted"],
)
def test_a_damaged_log_is_refused_not_read_past(
    built: Path, tmp_path: Path, damage: object, said: str
) -> None:
    """A commit file cut or garbled, or one between two others deleted (run cup's): refused
    with the words ``LakeBase.table()`` gives delta-rs's refusal, by ``where`` and ``replay``
    of any run too, never a traceback or an answer without the commit."""
    lake = _copy(built, tmp_path / "lake")
    damage(_commit(lake, 2))  # type: ignore[operator]
    with pytest.raises(TableLakeError, match="is damaged and cannot be read") as refused:
        _listing(lake)
    assert said in str(refused.value)
    for argv in (["where", "Apple", str(lake), "--run", "apple"], ["replay", str(lake), "--run", "apple"]):  # fmt: skip
        outcome = run_cli(argv)
        assert outcome.code == 2, (argv, outcome)
        assert "objsearch: error: " in outcome.stderr and "Traceback" not in outcome.stderr
        assert "damaged" in outcome.stderr, outcome.stderr


def test_an_add_removed_from_the_runs_commit_is_still_refused(built: Path, tmp_path: Path) -> None:
    """The listing reads what the log says; a run whose file's ``add`` was cut from its commit
    reads back short, and its digest refuses it (the check the listing does not replace)."""
    lake = _copy(built, tmp_path / "lake")
    path = _commit(lake, 2)  # run cup's
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(x for x in lines if '"path":"type=moved/' not in x))
    outcome = run_cli(["where", "Cup", str(lake), "--run", "cup"])
    assert outcome.code == 2 and "is damaged" in outcome.stderr, outcome


def test_where_and_replay_from_a_lake_run_load_no_delta_rs(built: Path) -> None:
    """Listing the run's files took delta-rs (~30 MB) only to read the log's JSON."""
    probe = (
        "import sys\n"
        "from objsearch.cli import main\n"
        "code = main(sys.argv[1:])\n"
        "print('DELTALAKE', 'deltalake' in sys.modules, code)\n"
    )
    for argv in (["where", "Apple", str(built), "--run", "apple"], ["replay", str(built), "--run", "apple"]):  # fmt: skip
        done = subprocess.run(
            [sys.executable, "-c", probe, *argv, "--no-progress"],
            capture_output=True,
            text=True,
            check=False,
        )
        assert "DELTALAKE False 0" in done.stdout, (argv, done.stdout[-500:], done.stderr[-2000:])


def test_a_commit_file_gone_between_listing_and_reading_is_looked_for_again(
    built: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A compaction that checkpoints the log and cleans up the commits before it may take a
    commit file away between the listing of the folder and its read: the log is read again once
    (then it finds the checkpoint and leaves the table to delta-rs) before it is called damaged.
    The race is made by failing the reads of version 1's file (as if deleted in between)."""
    expected = _listing(built)
    assert expected is not None
    real = Path.read_text
    gone = {"times": 1}

    def read_text(self: Path, *args: object, **kwargs: object) -> str:
        if self.name == f"{1:020d}.json" and gone["times"] > 0:
            gone["times"] -= 1
            raise FileNotFoundError(2, "No such file or directory", str(self))
        return real(self, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(Path, "read_text", read_text)
    again = _listing(built)
    assert again is not None
    assert again.get_add_actions().equals(expected.get_add_actions())
    gone["times"] = 2  # gone for good: damage
    with pytest.raises(TableLakeError, match="is damaged and cannot be read"):
        _listing(built)
