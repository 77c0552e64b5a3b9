"""docs/results.md's commands are full command lines that run as written from a clean clone: each
parses with the CLI's own parser, in the page's order every input is made by an earlier command,
every home a bench names exists in the data folder it reads, and the data builds (seconds each)
run for real. The bench runs themselves take minutes to hours and are not run here."""

from __future__ import annotations

import argparse
import json
import shlex
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from devtools import cli_battery as battery
from objsearch import cli_types as t
from objsearch.agent.datapaths import data_dir
from objsearch.cli import build_parser, main
from objsearch.experiments.homes import RENAMED_OPTIONS, data_build_commands, homes_command

REPO = Path(__file__).resolve().parents[2]
RESULTS = REPO / "docs" / "results.md"


@dataclass(frozen=True, slots=True)
class Command:
    env: dict[str, str]
    argv: list[str]  # after "objsearch"
    text: str


def _split(text: str) -> Command:
    words = shlex.split(text)
    env = {}
    while words and "=" in words[0] and not words[0].startswith("-"):
        name, value = words.pop(0).split("=", 1)
        env[name] = value
    assert words[:1] == ["objsearch"], f"not an objsearch command: {text}"
    return Command(env, words[1:], text)


def sequence(text: str) -> list[Command]:
    """The page's reproduction: the first ```sh block."""
    block = text.split("```sh\n", 1)[1].split("```", 1)[0]
    return [_split(line) for line in block.splitlines() if line.strip()]


def every_command(text: str) -> list[Command]:
    """Every command on the page: each line of its ```sh blocks and each `objsearch …` span."""
    found: list[str] = []
    for i, part in enumerate(text.split("```")):
        if i % 2:  # inside a fence
            if part.startswith("sh\n"):
                found += [line for line in part[3:].splitlines() if line.strip()]
            continue
        for span in part.split("`")[1::2]:
            words = span.split()
            rest = [w for w in words if "=" not in w or w.startswith("-")]
            if rest[:1] == ["objsearch"] and "\n" not in span:
                found.append(span)
    return [_split(c) for c in found]


@dataclass
class Clone:
    """What the commands have made so far in a scratch clone."""

    root: Path
    outs: set[str] = field(default_factory=set)
    data_homes: dict[str, set[str]] = field(default_factory=dict)


def _parse(cmd: Command, capsys: pytest.CaptureFixture[str]) -> argparse.Namespace:
    try:
        return build_parser().parse_args(cmd.argv)
    except SystemExit:
        pytest.fail(f"does not parse: {cmd.text}\n{capsys.readouterr().err}")


@pytest.fixture
def clone(tmp_path: Path, shared_data: Path, monkeypatch: pytest.MonkeyPatch) -> Clone:
    """An empty folder standing for a clean clone, with ../shared/data beside it."""
    (tmp_path / "shared").mkdir()
    (tmp_path / "shared" / "data").symlink_to(shared_data, target_is_directory=True)
    root = tmp_path / "clone"
    root.mkdir()
    monkeypatch.chdir(root)
    monkeypatch.delenv("OBJSEARCH_DATA", raising=False)
    return Clone(root)


def test_results_commands_run_as_written_from_a_clean_clone(
    clone: Clone, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    default_homes = {p.stem for p in (data_dir() / "homes").glob("*.json")}
    commands = sequence(RESULTS.read_text(encoding="utf-8"))
    assert commands[-1].argv[:2] == ["bench", "report"]
    built = 0
    for cmd in commands:
        assert set(cmd.env) <= {"OBJSEARCH_DATA"}, cmd.text
        data = cmd.env.get("OBJSEARCH_DATA")
        assert data is None or data in clone.data_homes, f"{data} is built by no earlier command"
        args = _parse(cmd, capsys)
        area = cmd.argv[:2]
        if area == ["data", "build"]:
            # Cheap (seconds): run it for real and note the homes it wrote.
            assert main(cmd.argv) == 0, cmd.text
            capsys.readouterr()
            out = args.out
            clone.data_homes[out] = {p.stem for p in (Path(out) / "homes").glob("*.json")}
            built += 1
            continue
        homes = default_homes if data is None else clone.data_homes[data]
        if area == ["bench", "homes"]:
            wanted = set(args.homes or ())
            assert wanted <= homes, f"unknown home(s) {sorted(wanted - homes)}: {cmd.text}"
        if area == ["bench", "report"]:
            assert args.paper is not None, f"the page's report names its --paper: {cmd.text}"
            inputs = [args.paper, *(args.evaluation or ()), *(args.heldout or ())]
            inputs += [*(args.table1 or ())]
            inputs += [args.paper_geometric] if args.paper_geometric else []
            missing = [str(d) for d in inputs if str(d) not in clone.outs]
            assert not missing, f"made by no earlier command: {missing}"
            continue
        out = args.out
        clone.outs.add(str(out))
        Path(out).mkdir(parents=True, exist_ok=True)  # what the run would leave for later ones
    assert built >= 2


def test_every_command_on_the_page_parses(clone: Clone, capsys: pytest.CaptureFixture[str]) -> None:
    commands = every_command(RESULTS.read_text(encoding="utf-8"))
    assert len(commands) > 20
    for cmd in commands:
        for name in ("table1", "heldout", "paper_geometric"):  # inputs that must exist to parse
            for i, word in enumerate(cmd.argv[:-1]):
                if word == "--" + name.replace("_", "-"):
                    Path(cmd.argv[i + 1]).mkdir(parents=True, exist_ok=True)
        _parse(cmd, capsys)


def test_a_command_with_a_home_no_build_made_fails_the_check(
    clone: Clone, capsys: pytest.CaptureFixture[str]
) -> None:
    """The check above catches the page's old fault: a held-out run without its data build."""
    cmd = _split("objsearch bench homes --out out/h --homes ithor-07,klbr-8 --seeds 5")
    args = _parse(cmd, capsys)
    default_homes = {p.stem for p in (data_dir() / "homes").glob("*.json")}
    assert not set(args.homes) <= default_homes
    with pytest.raises(pytest.fail.Exception, match="does not parse"):
        _parse(_split("objsearch bench homes; objsearch bench homes"), capsys)


def test_a_summary_without_its_command_gets_a_full_one(tmp_path: Path) -> None:
    """Runs from before summaries recorded their command (and camera: the geometric one)."""
    summary = {
        "homes": ["ithor-02", "procthor-00"],
        "schedules": ["habit"],
        "seeds": [0, 1],
        "scenes": 20,
        "starts_per_search": 2,
        "workers": 1,
        "strategies": {"wpl": {}, "ecost": {}, "wpl/none": {}},
    }
    command = homes_command(summary, tmp_path / "run")
    assert command == (
        f"objsearch bench homes --out {tmp_path / 'run'} --homes ithor-02,procthor-00 "
        "--schedules habit --seeds 2 --scenes-per-schedule 20 --strategies wpl,ecost "
        "--starts-per-scene 2 --workers 1 "
        "--camera geometric"
    )
    assert homes_command({**summary, "camera": "occluding"}, tmp_path).count("--camera") == 0
    build_parser().parse_args(shlex.split(command)[1:])


def test_a_recorded_command_is_shown_with_todays_option_names(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Runs recorded before --scenes/--starts became counts per schedule and scene: the page shows
    their command as today's CLI spells it, so a reader who copies it gets no deprecation note."""
    leaves = dict(battery.leaf_parsers(build_parser()))
    aliases = {
        option: action.new
        for action in leaves[("bench", "homes")]._actions
        if isinstance(action, t.Deprecated) and action.dest != "format"
        for option in action.option_strings
    }
    assert aliases == RENAMED_OPTIONS
    recorded = "objsearch bench homes --out out/h --homes ithor-02 --seeds 2 --scenes 15 --starts 1"
    command = homes_command({"command": recorded, "camera": "occluding"}, tmp_path)
    assert command.endswith("--seeds 2 --scenes-per-schedule 15 --starts-per-scene 1")
    capsys.readouterr()
    build_parser().parse_args(shlex.split(command)[1:])
    assert capsys.readouterr().err == ""


def test_a_bench_on_a_data_folder_records_its_build(
    clone: Clone, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    build = "data build --source ../shared/data --out mydata --heldout-ithor 11"
    assert main(build.split()) == 0
    assert data_build_commands(Path("mydata")) == [
        "objsearch data build --source ../shared/data --heldout-ithor 11 --out mydata"
    ]
    monkeypatch.setenv("OBJSEARCH_DATA", "mydata")
    argv = ["bench", "homes", "--out", "out/h", "--homes", "ithor-11", "--scenes-per-schedule", "1"]
    assert main([*argv, "--strategies", "wpl", "--workers", "1", "--no-progress"]) == 0
    capsys.readouterr()
    summary = json.loads(Path("out/h/summary.json").read_text(encoding="utf-8"))
    assert summary["command"].startswith("OBJSEARCH_DATA=mydata objsearch bench homes --out out/h")
    assert summary["data_build"] == data_build_commands(Path("mydata"))
