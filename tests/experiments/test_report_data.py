"""``bench belief`` over outputs run on different data folders (experiments/report_data.py):
each output's homes from the folder it was run on, else ``--data``; a home no folder holds and
one home id with two contents are errors."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from objsearch.agent.datapaths import DATA_ENV, data_dir
from objsearch.cli import main
from objsearch.experiments.report_data import recorded_data_folder

from .env_writes import env_writes

MAIN = "import sys; from objsearch.cli import main; sys.exit(main(sys.argv[1:]))"

#: A tiny habit run: 12 scenes, so the usual-place table (after day 10) reads the home itself.
RUN = [
    "--schedules", "habit", "--seeds", "1", "--scenes-per-schedule", "12",
    "--strategies", "global-belief", "--starts-per-scene", "1", "--workers", "1", "--no-progress",
]  # fmt: skip


def _data_folder(path: Path, rename: tuple[str, str] | None = None, indent: bool = False) -> Path:
    """A copy of the bundled data, with one home renamed (a home only it holds) or one home
    file written again with other whitespace (same id, other content)."""
    shutil.copytree(data_dir(), path, ignore=shutil.ignore_patterns("__pycache__"))
    if rename is not None:
        old, new = rename
        doc = json.loads((path / "homes" / f"{old}.json").read_text(encoding="utf-8"))
        doc["name"] = new
        (path / "homes" / f"{new}.json").write_text(json.dumps(doc), encoding="utf-8")
    if indent:
        home = path / "homes" / "ithor-01.json"
        home.write_text(json.dumps(json.loads(home.read_text(encoding="utf-8")), indent=1))
    return path


def _bench_homes(out: Path, home: str, data: Path | None) -> Path:
    with pytest.MonkeyPatch.context() as mp:
        if data is None:
            mp.delenv(DATA_ENV, raising=False)
        else:
            mp.setenv(DATA_ENV, str(data))
        assert main(["bench", "homes", "--out", str(out), "--homes", home, *RUN]) == 0
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """``bundled``: ithor-01 on the bundled data; ``other``: alt-01, a home only the data folder
    ``other_data`` holds."""
    root = tmp_path_factory.mktemp("runs")
    other_data = _data_folder(root / "other-data", rename=("ithor-01", "alt-01"))
    return {
        "bundled": _bench_homes(root / "bundled", "ithor-01", None),
        "other": _bench_homes(root / "other", "alt-01", other_data),
        "other_data": other_data,
    }


def _belief(
    capsys: pytest.CaptureFixture[str], out: Path, *args: str | Path
) -> tuple[int, str, str]:
    code = main(["bench", "belief", *map(str, args), "--out", str(out), "--no-progress"])
    printed = capsys.readouterr()
    return code, printed.out, printed.err


def test_outputs_run_on_two_data_folders_are_pooled(
    runs: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv(DATA_ENV, raising=False)
    code, out, err = _belief(capsys, tmp_path / "r", runs["bundled"], runs["other"])
    assert code == 0, err
    assert "homes (2): alt-01, ithor-01;" in out
    # The usual-place table drew alt-01's schedule from the home in its own data folder.
    assert "On days the target was at its usual place" in out
    assert DATA_ENV not in os.environ  # the folder is not left set
    # In a process of its own, as a user runs it: nothing of the bench homes runs above is
    # cached (the schedule's redraws read the home's file again, by its id).
    env = {k: v for k, v in os.environ.items() if k != DATA_ENV}
    argv = ["bench", "belief", str(runs["bundled"]), str(runs["other"]), "--no-progress"]
    alone = subprocess.run(
        [sys.executable, "-c", MAIN, *argv, "--out", str(tmp_path / "alone")],
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    assert alone.returncode == 0, alone.stderr
    assert alone.stdout == out.replace(str(tmp_path / "r"), str(tmp_path / "alone"))


def test_an_outputs_data_folder_is_the_one_its_summary_records(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    assert recorded_data_folder(runs["other"]) == runs["other_data"]
    assert recorded_data_folder(runs["bundled"]) is None
    # Without OBJSEARCH_DATA in its command: the --out of its last data build.
    built = tmp_path / "built"
    built.mkdir()
    summary = {"command": "objsearch bench homes", "data_build": ["objsearch data build --out d"]}
    (built / "summary.json").write_text(json.dumps(summary), encoding="utf-8")
    assert recorded_data_folder(built) == Path("d")


def test_a_home_no_data_folder_holds_names_the_output_and_where_it_looked(
    runs: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv(DATA_ENV, raising=False)
    moved = tmp_path / "moved-data"
    shutil.move(runs["other_data"], moved)  # the folder the output was run on is gone
    try:
        code, _, err = _belief(capsys, tmp_path / "r", runs["bundled"], runs["other"])
        assert code == 2
        assert err.startswith(
            f"objsearch: error: output {runs['other']} ran on home 'alt-01', which no data "
            f"folder holds: looked for homes/alt-01.json in {runs['other_data']} (recorded in "
            f"its summary.json; no such folder); {data_dir()} ($OBJSEARCH_DATA, else the "
            "bundled data); name the folder it was run on with --data DIR"
        ), err
        # Named with --data, it is found there.
        code, out, err = _belief(
            capsys, tmp_path / "r", runs["bundled"], runs["other"], "--data", moved
        )
        assert code == 0, err
        assert "homes (2): alt-01, ithor-01;" in out
    finally:
        shutil.move(moved, runs["other_data"])


def test_one_home_id_with_two_contents_is_refused(
    runs: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv(DATA_ENV, raising=False)
    changed = _data_folder(tmp_path / "changed-data", indent=True)
    again = _bench_homes(tmp_path / "again", "ithor-01", changed)
    code, _, err = _belief(capsys, tmp_path / "r", runs["bundled"], again)
    assert code == 2
    assert err.startswith(
        f"objsearch: error: outputs {runs['bundled']} and {again} both name home 'ithor-01', "
        f"but its files differ ({data_dir() / 'homes' / 'ithor-01.json'} and "
        f"{changed / 'homes' / 'ithor-01.json'}): refusing to pool them"
    ), err
    # The same file in another folder is the same home: pooled.
    same = _data_folder(tmp_path / "same-data")
    twin = _bench_homes(tmp_path / "twin", "ithor-01", same)
    code, out, err = _belief(capsys, tmp_path / "r", runs["bundled"], twin)
    assert code == 0, err
    assert "homes (1): ithor-01;" in out


@pytest.mark.parametrize(
    ("folder", "message"),
    [
        ("missing", "bench belief: argument --data: no such folder: {}"),
        ("empty", "--data {}: not a data folder (no homes/ in it;"),
    ],
)
def test_data_must_name_a_data_folder(
    runs: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    folder: str,
    message: str,
) -> None:
    (tmp_path / "empty").mkdir()
    path = tmp_path / folder
    code, _, err = _belief(capsys, tmp_path / "r", runs["bundled"], "--data", path)
    assert code == 2
    assert f"objsearch: error: {message.format(path)}" in err


def test_pooling_sets_no_environment_variable(
    runs: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Each output's folder is handed to the readers, not set as $OBJSEARCH_DATA around them:
    nothing is set or unset in the environment while ``bench belief`` runs (an audit hook sees
    every write to it)."""
    monkeypatch.delenv(DATA_ENV, raising=False)
    before = dict(os.environ)
    with env_writes() as writes:
        code, out, err = _belief(capsys, tmp_path / "r", runs["bundled"], runs["other"])
    assert code == 0, err
    assert "homes (2): alt-01, ithor-01;" in out
    assert "On days the target was at its usual place" in out
    assert writes == []
    assert dict(os.environ) == before
