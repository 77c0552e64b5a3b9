"""The bad-input battery: every subcommand's every option with malformed values ends in
``objsearch: error: …`` and exit 2, never a traceback (devtools/cli_battery.py builds the cases;
benchmarks/bad_inputs.py runs a larger set and real processes)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from devtools import cli_battery as battery
from devtools.cli_process import run_cli
from objsearch.cli import build_parser

#: A subset of the battery's values, one of each kind, so CI stays within seconds.
CI_VALUES = ("", "-1", "nan", "1e400", "abc", "garbage", "a\nb")
CI_PATHS = (battery.FILE, battery.DIR, battery.MISSING)

COMMANDS = [" ".join(words) for words, _ in battery.leaf_parsers(build_parser())]


@pytest.fixture(scope="module")
def scratch(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return battery.prepare(tmp_path_factory.mktemp("battery"))


def test_the_battery_walks_every_subcommand() -> None:
    assert {"search", "demo", "ingest", "record", "query", "lake add", "bench paper"} <= set(
        COMMANDS
    )
    assert {"agent run", "robot router", "map build", "data build", "liveview"} <= set(COMMANDS)


def test_every_option_is_validated() -> None:
    assert battery.unvalidated(build_parser()) == []


@pytest.mark.parametrize("command", COMMANDS)
def test_malformed_values_are_clear_errors(command: str, scratch: Path) -> None:
    wanted = {*CI_VALUES, *(str(scratch / p) for p in CI_PATHS)}
    tried, failures = 0, []
    parser = build_parser()
    for case in battery.cases(parser, scratch):
        if " ".join(case.command) != command or not case.invalid or case.value not in wanted:
            continue
        tried += 1
        outcome = battery.run_in_process(case.argv, guard=parser)
        if outcome.verdict != "clear error" or f"argument {case.option}" not in outcome.stderr:
            failures.append(f"{case.argv}: exit {outcome.code}: {outcome.stderr[-300:]}")
    assert not failures, "\n".join(failures)
    options = battery.value_actions(
        dict(battery.leaf_parsers(build_parser()))[tuple(command.split())]
    )
    assert tried >= len(options)  # at least one malformed value per option


def test_the_battery_reports_a_traceback_as_such() -> None:
    # A case whose command fails with a bug (not an expected error) must not pass as clear.
    assert (
        battery.BatteryOutcome(1, "", "Traceback (most recent call last):\n  …").verdict
        == "traceback"
    )
    assert battery.BatteryOutcome(2, "", "objsearch: error: x\n").verdict == "clear error"
    assert battery.BatteryOutcome(0, "ok", "").verdict == "other"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["ingest", ".", "--lake", "lake", "--workers", "300"], "between 1 and 64, not 300"),
        (["record", "--out", "x.bag", "--bag-format", "ros1", "--odom-hz", "1e9"], "at most 200"),
        (["agent", "run", "--log", "log", "--listen", "garbage"], "zenoh endpoint"),
        (["bench", "paper", "--scenes", "99"], "between 1 and 10, not 99"),
        (["demo", "--out", ""], "the path is empty"),
        (["bench", "paper", "--targets", "Cat"], "Cat not among the eight targets"),
    ],
)
def test_bad_inputs_in_a_real_process(tmp_path: Path, args: list[str], message: str) -> None:
    proc = run_cli(*args, cwd=tmp_path)
    assert proc.returncode == 2
    assert "objsearch: error: " in proc.stderr and message in proc.stderr
    assert "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == []  # nothing was made


@pytest.mark.parametrize("args", [["--help"], ["demo", "--help"], ["map", "show"]])
def test_an_ascii_only_terminal_gets_escapes_not_a_crash(args: list[str]) -> None:
    proc = run_cli(*args, env={"PYTHONIOENCODING": "ascii"})
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    proc.stdout.encode("ascii")  # what reached the terminal is ASCII


def test_an_ascii_only_terminal_gets_error_messages(tmp_path: Path) -> None:
    proc = run_cli("graph", str(tmp_path / "ŝtrange"), env={"PYTHONIOENCODING": "ascii"})
    assert proc.returncode == 2
    assert "objsearch: error: " in proc.stderr and "Traceback" not in proc.stderr


def test_map_show_json_still_parses_on_an_ascii_terminal() -> None:
    proc = run_cli("map", "show", "--format", "json", env={"PYTHONIOENCODING": "ascii"})
    assert proc.returncode == 0
    assert json.loads(proc.stdout)["statics"]
