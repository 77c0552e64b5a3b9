"""Output folders: a command replaces only what it wrote, and refuses folders it did not write."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from objsearch.agent.outdir import MANIFEST, OutputDirError, claim
from objsearch.cli import main

OWNS = ("log-all", "table.csv")


def _earlier_run(out: Path) -> None:
    with claim(out, command="demo", owns=OWNS):
        (out / "log-all").mkdir()
        (out / "log-all" / "events.log").write_text("event\n")
        (out / "table.csv").write_text("a,b\n")


def _tree(root: Path) -> dict[str, str]:
    return {
        p.relative_to(root).as_posix(): p.read_text()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def test_a_new_folder_is_claimed_and_its_files_recorded(tmp_path: Path) -> None:
    out = tmp_path / "a" / "b"
    _earlier_run(out)
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["command"] == "demo" and manifest["complete"] is True
    assert manifest["files"] == ["log-all/events.log", "table.csv"]


def test_force_replaces_only_what_the_command_wrote(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    _earlier_run(out)
    (out / "notes.md").write_text("mine")
    (out / "precious").mkdir()
    (out / "precious" / "thesis.txt").write_text("years of work")
    with pytest.raises(OutputDirError, match="pass --force"):
        claim(out, command="demo", owns=OWNS)
    with claim(out, command="demo", owns=OWNS, force=True):
        assert not (out / "log-all").exists() and not (out / "table.csv").exists()
        (out / "table.csv").write_text("new\n")
    assert _tree(out) == {
        MANIFEST: (out / MANIFEST).read_text(),
        "notes.md": "mine",
        "precious/thesis.txt": "years of work",
        "table.csv": "new\n",
    }


def test_a_folder_the_command_did_not_write_is_refused_and_untouched(tmp_path: Path) -> None:
    out = tmp_path / "thesis"
    (out / "precious").mkdir(parents=True)
    (out / "notes.md").write_text("mine")
    (out / "precious" / "thesis.txt").write_text("years of work")
    before = _tree(out)
    with pytest.raises(OutputDirError, match=r"not written by objsearch demo.*nothing was deleted"):
        claim(out, command="demo", owns=OWNS, force=True)
    assert _tree(out) == before


def test_unknown_files_where_the_command_writes_are_refused(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    _earlier_run(out)
    (out / "log-all" / "my-notes.txt").write_text("mine")
    before = _tree(out)
    with pytest.raises(OutputDirError, match=r"did not write.*my-notes\.txt"):
        claim(out, command="demo", owns=OWNS, force=True)
    assert _tree(out) == before


def test_another_commands_output_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "out"
    _earlier_run(out)
    with pytest.raises(OutputDirError, match="holds the output of objsearch demo"):
        claim(out, command="audit", owns=("index.md",), replace_needs_force=False)


def test_a_file_or_an_empty_path_is_refused(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    with pytest.raises(OutputDirError, match="is a file"):
        claim(tmp_path / "f", command="demo", owns=OWNS)
    with pytest.raises(OutputDirError, match="empty"):
        claim(Path(""), command="demo", owns=OWNS)


def test_an_interrupted_run_still_records_what_it_wrote(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    with pytest.raises(KeyboardInterrupt), claim(out, command="demo", owns=OWNS):
        (out / "table.csv").write_text("half")
        raise KeyboardInterrupt
    assert json.loads((out / MANIFEST).read_text())["files"] == ["table.csv"]
    with claim(out, command="demo", owns=OWNS, force=True):
        assert not (out / "table.csv").exists()


def test_demo_force_refuses_someones_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "work"
    (out / "precious").mkdir(parents=True)
    (out / "notes.md").write_text("mine")
    (out / "precious" / "thesis.txt").write_text("years of work")
    before = _tree(out)
    assert main(["demo", "--out", str(out), "--force", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("objsearch: error: ") and "nothing was deleted" in err
    assert _tree(out) == before


@pytest.mark.parametrize("out", ["", " "])
def test_demo_refuses_an_empty_out(out: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--out", out, "--force"]) == 2
    assert "argument --out: the path is empty" in capsys.readouterr().err


def test_a_run_that_wrote_nothing_gives_the_folder_back(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with pytest.raises(ValueError), claim(out, command="demo", owns=OWNS):
        raise ValueError("unknown home")
    assert list(out.iterdir()) == []
    with claim(out, command="audit", owns=("index.md",)):
        (out / "index.md").write_text("# audit")


def test_a_run_that_fails_before_writing_gives_the_earlier_output_back(tmp_path: Path) -> None:
    """A bench run with an unknown home once emptied the folder of the run before it."""
    out = tmp_path / "demo"
    _earlier_run(out)
    before = _tree(out)
    with pytest.raises(ValueError), claim(out, command="demo", owns=OWNS, force=True):
        assert not (out / "table.csv").exists()  # set aside while the new run runs
        raise ValueError("unknown home")
    assert _tree(out) == before


def test_a_run_killed_while_the_earlier_output_is_set_aside_gets_it_back(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    _earlier_run(out)
    before = _tree(out)
    claim(out, command="demo", owns=OWNS, force=True)  # never exited: the process died
    assert not (out / "table.csv").exists()
    with claim(out, command="demo", owns=OWNS, force=True):
        pass  # restores, sets aside again, writes nothing, fails nothing
    assert _tree(out) == before
    with claim(out, command="demo", owns=OWNS, force=True):
        (out / "table.csv").write_text("new\n")
    assert _tree(out) == {MANIFEST: (out / MANIFEST).read_text(), "table.csv": "new\n"}


def test_bench_homes_with_an_unknown_home_keeps_the_earlier_results(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """It once emptied the folder first, then found the home unknown."""
    out = tmp_path / "bench"
    with claim(
        out, command="bench homes", owns=("homes_trials.parquet",), replace_needs_force=False
    ):
        (out / "homes_trials.parquet").write_bytes(b"PAR1 earlier results")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    argv = ["bench", "homes", "--out", str(out), "--no-progress", "--workers", "1"]
    assert main([*argv, "--homes", "ithor-99", "--strategies", "wpl"]) == 2
    assert "unknown home(s) ithor-99" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
