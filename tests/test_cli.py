"""The command line: what a user sees for good and bad input."""

from __future__ import annotations

import json
import logging
import os
import shutil
from pathlib import Path

import pytest

from devtools.cli_process import run_cli
from objsearch.agent.catalogue import STORE
from objsearch.agent.datapaths import data_dir
from objsearch.cli import main
from objsearch.events import read_log


def test_search_prints_the_route_and_writes_the_log(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "log"
    code = main(
        [
            "search",
            "phone",
            "--start",
            "living-1",
            "--log",
            str(log),
            "--format",
            "json",
        ]
    )
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    assert out["target"] == "Phone"  # the alias resolved
    assert out["success"] is True
    assert out["path_length_m"] >= out["oracle_length_m"] > 0
    assert out["route"][0] != out["route"][-1]
    events = list(read_log(log, store=STORE))
    assert events[-1].type == "task_ended"
    assert events[-1].payload["path_length"] == pytest.approx(out["path_length_m"], abs=1e-3)


def test_search_says_where_it_found_the_target(capsys: pytest.CaptureFixture[str]) -> None:
    # The README's first example: the paper home's Apple is in the kitchen's fridge.
    assert main(["search", "Apple", "--start", "kitchen-1", "--format", "json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["found_at"]["room"] == "kitchen" and out["found_at"]["inside"] is True
    assert out["found_at"]["static_id"].startswith("kitchen/Fridge|")
    assert 0 < out["path_to_discovery_m"] <= out["path_length_m"]
    assert main(["search", "Apple", "--start", "kitchen-1"]) == 0
    text = capsys.readouterr().out.splitlines()
    where = f"  found {out['found']} inside {out['found_at']['static_id'].split('/', 1)[1]}"
    assert text[1] == f"{where} in kitchen, seen after {out['path_to_discovery_m']:.2f} m"


def test_the_readme_explains_its_first_example_with_what_it_prints(
    capsys: pytest.CaptureFixture[str],
) -> None:
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    why = readme.split("**Why `objsearch search Apple --start kitchen-1` walks ", 1)[1]
    why = why.split("\n\n", 1)[0]
    lengths = {}
    for strategy in ("global-belief+cover", "wpl"):
        argv = ["search", "Apple", "--start", "kitchen-1", "--strategy", strategy]
        assert main([*argv, "--format", "json"]) == 0
        lengths[strategy] = json.loads(capsys.readouterr().out)["path_to_discovery_m"]
    assert why.startswith(f"{lengths['global-belief+cover']:.2f} m")
    assert f"opens the fridge third: {lengths['wpl']:.2f} m" in why


def test_the_readme_first_examples_other_figures_are_what_the_commands_print(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """From kitchen-2, and the same command again with the first search's log."""
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    why = readme.split("**Why `objsearch search Apple --start kitchen-1` walks ", 1)[1]
    why = " ".join(why.split("\n\n", 1)[0].split())
    lengths = {}
    for strategy in ("global-belief+cover", "wpl"):
        argv = ["search", "Apple", "--start", "kitchen-2", "--strategy", strategy]
        assert main([*argv, "--format", "json"]) == 0
        lengths[strategy] = json.loads(capsys.readouterr().out)["path_to_discovery_m"]
    k2 = f"From `kitchen-2` it is {lengths['global-belief+cover']:.2f} m against wpl's"
    assert f"{k2} {lengths['wpl']:.2f} m" in why
    log = tmp_path / "log"
    for _ in range(2):
        argv = ["search", "Apple", "--start", "kitchen-1", "--log", str(log), "--format", "json"]
        assert main(argv) == 0
        second = json.loads(capsys.readouterr().out)["path_to_discovery_m"]
    assert f"finds the Apple after {second:.2f} m" in why


@pytest.mark.parametrize("camera", ["occluding", "geometric"])
def test_search_records_its_camera_and_the_camera_tilt(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], camera: str
) -> None:
    log = tmp_path / "log"
    args = ["search", "Pillow", "--start", "kitchen-1", "--camera", camera]
    assert main([*args, "--log", str(log), "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out)["camera"] == camera
    events = list(read_log(log, store=STORE))
    (started,) = (e for e in events if e.type == "run_started")
    assert started.payload["params"]["camera"] == camera
    looks = [e.payload["pitch"] for e in events if e.type == "view_taken"]
    assert looks and any(p > 0 for p in looks)  # tilted at what it inspects


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["Apple", "--start", "kitchen-1", "--camera", "x-ray"], "--camera"),
        (["Spaceship", "--start", "kitchen-1"], "unknown object class 'Spaceship'"),
        (["Fridge", "--start", "kitchen-1"], "static object and cannot be a search"),
        (["Apple", "--start", "garage-3"], "unknown start point 'garage-3'"),
        (["Apple", "--start", "kitchen-1", "--home", "castle"], "no home 'castle'"),
        (["Apple", "--start", "kitchen-1", "--scene", "99"], "not 99"),
        # Another home with the paper's schedule: the error names the option that fixes it.
        (
            ["Apple", "--start", "kitchen-1", "--home", "ithor-01", "--scene", "2"],
            "is the paper home's only; pass --schedule stats-<seed>",
        ),
        # A class the home does not place: nothing to find (was a ValueError traceback).
        (
            ["Cup", "--start", "kitchen-1", "--home", "procthor-00"],
            "no Cup is placed in procthor-00 (its own placements)",
        ),
    ],
)
def test_bad_search_input_is_a_clear_error_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    log = tmp_path / "log"
    assert main(["search", *args, "--log", str(log)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("objsearch: error: ")
    assert message in err
    assert not log.exists()


def test_a_search_on_another_home_places_its_objects_as_its_source_scene(
    capsys: pytest.CaptureFixture[str],
) -> None:
    # It once applied the paper home's Table I removals and failed on objects ithor-01 lacks.
    argv = ["search", "Apple", "--start", "kitchen-1", "--home", "ithor-01", "--format", "json"]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["success"] and summary["path_length_m"] >= summary["oracle_length_m"] > 0


def test_demo_on_another_home_says_what_runs_there(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["demo", "--home", "ithor-01", "--out", str(tmp_path / "demo")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("objsearch: error: demo on home 'ithor-01'")
    assert "objsearch bench homes --homes ithor-01" in err and "--schedule stats-0" in err
    assert not (tmp_path / "demo").exists()


def _data_copy(tmp_path: Path, *, drop: str) -> dict[str, str]:
    copy = tmp_path / "data"
    shutil.copytree(data_dir(), copy)
    (copy / drop).unlink()
    return {**os.environ, "OBJSEARCH_DATA": str(copy)}


@pytest.mark.parametrize(
    "missing", ["priors/visual_genome.json", "vocabulary.json", "homes/paper.json"]
)
def test_a_missing_data_file_is_named_and_nothing_is_written(tmp_path: Path, missing: str) -> None:
    env = _data_copy(tmp_path, drop=missing)
    log = tmp_path / "log"
    proc = run_cli("search", "Apple", "--start", "kitchen-1", "--log", str(log), env=env)
    assert proc.returncode == 2
    assert proc.stderr.startswith("objsearch: error: ")
    assert Path(missing).stem in proc.stderr
    assert "Traceback" not in proc.stderr
    assert not (log / "events.log").exists() or not list(read_log(log, store=STORE))


def _logged_search(log: Path, target: str = "Apple") -> None:
    assert main(["search", target, "--start", "kitchen-1", "--log", str(log)]) == 0


def test_a_corrupted_log_is_refused_with_its_position_and_left_as_it_was(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "log"
    _logged_search(log)
    path = log / "events.log"
    data = bytearray(path.read_bytes())
    at = data.index(b"task_started")
    data[at] ^= 0x20  # flip one bit of a record in the middle
    path.write_bytes(bytes(data))
    capsys.readouterr()

    assert main(["search", "Cup", "--start", "kitchen-1", "--log", str(log)]) == 2
    err = capsys.readouterr().err
    assert "corrupt event log" in err and "line 3" in err and "byte offset" in err
    assert path.read_bytes() == bytes(data)
    assert main(["graph", str(log)]) == 2
    assert path.read_bytes() == bytes(data)


def test_a_torn_tail_is_cut_with_a_warning_and_acknowledged_events_survive(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    log = tmp_path / "log"
    _logged_search(log)
    acknowledged = list(read_log(log, store=STORE))
    path = log / "events.log"
    with path.open("ab") as f:  # an append interrupted half way through its line
        f.write(b'{"event_id": "x", "stream": "robot", "seq": ')
    capsys.readouterr()

    with caplog.at_level(logging.WARNING):
        _logged_search(log, "Cup")
    assert "torn tail" in caplog.text and "cut 44 byte(s)" in caplog.text
    events = list(read_log(log, store=STORE))
    assert events[: len(acknowledged)] == acknowledged
    assert [e.seq for e in events] == list(range(1, len(events) + 1))


def test_graph_until_seq(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "log"
    _logged_search(log)
    last = list(read_log(log, store=STORE))[-1].seq
    capsys.readouterr()
    assert main(["graph", str(log), "--until", "2", "--format", "json"]) == 0
    at2 = json.loads(capsys.readouterr().out)
    assert main(["graph", str(log), "--format", "json"]) == 0
    now = json.loads(capsys.readouterr().out)
    assert (at2["seq"], at2["tasks"], now["seq"], now["tasks"]) == (2, 0, last, 1)
    assert at2["relations"]["Apple"] != now["relations"]["Apple"]
    assert main(["graph", str(log), "--until", str(last + 1)]) == 2
    assert f"ends at seq {last}" in capsys.readouterr().err


def test_graph_of_a_missing_log_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["graph", str(tmp_path / "nowhere")]) == 2
    assert "objsearch: error:" in capsys.readouterr().err
    assert not (tmp_path / "nowhere").exists()


def test_help_works_everywhere() -> None:
    for args in (["--help"], ["search", "--help"], ["demo", "--help"], ["graph", "--help"]):
        proc = run_cli(*args)
        assert proc.returncode == 0, proc.stderr
        assert "usage: objsearch" in proc.stdout
