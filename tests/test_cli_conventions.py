"""One CLI convention across commands (DEVELOPERS.md, "CLI conventions"), checked over the whole
parser tree, so a new command or option that strays fails here: one output-format option, list
options that are comma-separated and repeatable, ``--scenes``/``--starts`` with one meaning,
inputs positional, ``--no-progress`` on every long command — and every old spelling still
parses, with a note on stderr."""

from __future__ import annotations

import argparse
import io
import re
import shutil
import sys
from pathlib import Path

import pytest

from devtools import cli_battery as battery
from objsearch import cli_types as t
from objsearch.cli import build_parser, main

REPO = Path(__file__).resolve().parents[1]
LEAVES = {" ".join(words): leaf for words, leaf in battery.leaf_parsers(build_parser())}
#: The list types of cli_types (each returns a list from one comma-separated value).
LIST_TYPES = {"name_list", "int_list", "float_list", "subset_of", "number_spans"}
#: Repeatable options whose values may hold commas (paths, endpoints, NAME=FILE pairs).
REPEATED_ONLY_TYPES = {"dir_path", "existing_dir", "text", "zenoh_endpoint", "host"}
#: Commands that can run longer than a few seconds (a bench, a whole log or lake, a data build).
LONG_COMMANDS = {
    "demo",
    "record",
    "ingest",
    "data build",
    "bench paper",
    "bench homes",
    "bench sensitivity",
    "bench table1",
    "bench dhs",
    "bench stot",
    "bench report",
    "bench belief",
    "map build",
    "replay",
    "audit",
    "liveview",
    "lake add",
    "lake upgrade",
    "lake verify",
    "log verify",
    "log repair",
    "graph",
    "where",
}
#: Pages whose commands the lead regenerates from recorded runs: old spellings may stay there
#: (they still parse, tests/experiments/test_results_commands.py).
REGENERATED = {"docs/results.md", "docs/results-belief.md"}


def _options(leaf: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {o: a for a in leaf._actions for o in a.option_strings}


def _type_name(action: argparse.Action) -> str:
    return str(getattr(action.type, "__name__", action.type))


def test_one_output_format_option() -> None:
    for command, leaf in LEAVES.items():
        options = _options(leaf)
        if "--json" in options:
            alias = options["--json"]
            assert isinstance(alias, t.Deprecated), f"{command}: --json is not the alias"
            assert (alias.dest, alias.const) == ("format", "json"), command
            assert "--format" in options, f"{command}: --json without --format"
        if "--format" in options:
            fmt = options["--format"]
            assert fmt.choices is not None and "json" in fmt.choices, command
            assert fmt.default in ("text", "table"), f"{command}: --format is not an output format"


def test_lists_are_comma_separated_and_repeatable() -> None:
    for command, leaf in LEAVES.items():
        for action in leaf._actions:
            if not action.option_strings:
                continue
            name = f"{command} {action.option_strings[0]}"
            if _type_name(action) in LIST_TYPES or action.nargs in ("+", "*"):
                assert isinstance(action, t.ListAction), f"{name}: a list that cannot repeat"
                assert _type_name(action) in LIST_TYPES, f"{name}: not split on commas"
            if isinstance(action, argparse._AppendAction):
                assert _type_name(action) in REPEATED_ONLY_TYPES, f"{name}: use **t.LIST"


@pytest.mark.parametrize("option", ["--scenes", "--starts"])
def test_scenes_and_starts_name_which_ones(option: str) -> None:
    for command, leaf in LEAVES.items():
        action = _options(leaf).get(option)
        if action is None or isinstance(action, t.Deprecated):
            continue
        assert isinstance(action, t.ListAction), f"{command} {option} is not a list"


#: Value types that name a place (a file or a folder): an option's kind of value, whichever.
PLACE_TYPES = {
    "existing_dir",
    "existing_file",
    "existing_path",
    "dir_path",
    "file_path",
    "new_path",
}
#: Value types that name a thing (a home, a strategy): free text, or one of a command's choices.
NAME_TYPES = {"text", "None"}
#: Options whose place may also be an s3:// URI, so their type is text where a bucket is allowed.
URI_OPTIONS = {"--lake"}


def _kind(option: str, action: argparse.Action) -> str:
    name = _type_name(action)
    if name in PLACE_TYPES or (option in URI_OPTIONS and name == "text"):
        return "a place"
    return "a name" if name in NAME_TYPES else name


def test_an_option_means_one_thing_in_every_command() -> None:
    # --homes was home names in bench homes and folders in bench report; --at a sequence number
    # in graph and a time of the week in where.
    kinds: dict[str, dict[str, str]] = {}
    for command, leaf in LEAVES.items():
        for option, action in _options(leaf).items():
            if not isinstance(action, t.Deprecated):
                kinds.setdefault(option, {})[command] = _kind(option, action)
    mixed = {o: k for o, k in kinds.items() if len(set(k.values())) > 1}
    assert not mixed


def test_the_log_or_lake_a_command_reads_is_positional() -> None:
    for command, leaf in LEAVES.items():
        for option, action in _options(leaf).items():
            if option in ("--log", "--lake") and not isinstance(action, t.Deprecated):
                # An option --log or --lake is something written (or a lake with a default).
                assert _type_name(action) != "existing_dir", f"{command} {option}: positional"


def test_the_object_a_command_finds_is_positional() -> None:
    # search TARGET, as agent find TARGET and where TARGET (search --target is the old spelling).
    finders = {"search", "agent find", "agent where", "where"}
    for command in finders:
        positional = [a.metavar for a in LEAVES[command]._actions if not a.option_strings]
        assert positional[:1] == ["TARGET"], command
    for command, leaf in LEAVES.items():
        action = _options(leaf).get("--target")
        assert action is None or isinstance(action, t.Deprecated), f"{command} --target"


def _every_parser(
    parser: argparse.ArgumentParser, words: tuple[str, ...] = ()
) -> list[tuple[str, argparse.ArgumentParser]]:
    """The parser and every parser below it (commands with subcommands too), by their words."""
    found = [(" ".join(words) or "objsearch", parser)]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, child in action.choices.items():
                found += _every_parser(child, (*words, name))
    return found


def test_no_parser_accepts_an_abbreviated_option() -> None:
    parsers = _every_parser(build_parser())
    assert {"bench paper", "lake ls", "agent find"} <= {words for words, _ in parsers}
    lenient = [words for words, p in parsers if not isinstance(p, t.Parser) or p.allow_abbrev]
    assert not lenient


@pytest.mark.parametrize(
    "argv",
    [
        ["search", "Apple", "--start", "kitchen-1", "--strat", "wpl"],
        ["bench", "paper", "--strat", "wpl"],
        ["bench", "homes", "--seed", "2"],
    ],
)
def test_an_abbreviated_option_is_a_usage_error(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(argv)
    assert exit_.value.code == 2
    assert f"unrecognized arguments: {argv[-2]}" in capsys.readouterr().err


def test_long_commands_take_no_progress() -> None:
    assert set(LEAVES) >= LONG_COMMANDS
    missing = [c for c in sorted(LONG_COMMANDS) if "--no-progress" not in _options(LEAVES[c])]
    assert not missing


@pytest.mark.parametrize(
    ("argv", "attribute", "value", "note"),
    [
        (["map", "show", "--json"], "format", "json", "--json is deprecated"),
        (["map", "show", "--format", "json"], "format", "json", ""),
        (["record", "--out", "x.bag", "--format", "ros1"], "bag_format", "ros1", "--bag-format"),
        (["record", "--out", "x.bag", "--bag-format", "ros1"], "bag_format", "ros1", ""),
        (["record", "--out", "x.bag", "--bag-format", "ros1", "--scenes", "1", "2"], "scenes",
         [1, 2], "comma-separated"),
        (["record", "--out", "x.bag", "--bag-format", "ros1", "--scenes", "1,2", "--scenes", "3"],
         "scenes", [1, 2, 3], ""),
        (["bench", "paper", "--targets", "Apple", "--targets", "Cup,Vase"], "targets",
         ["Apple", "Cup", "Vase"], ""),
        (["bench", "homes", "--scenes", "12"], "scenes_per_schedule", 12, "--scenes is deprecated"),
        (["bench", "homes", "--starts", "2"], "starts_per_scene", 2, "--starts is deprecated"),
        (["bench", "homes", "--schedules", "habit", "--schedules", "stats"], "schedules",
         ["habit", "stats"], ""),
        (["graph", "--log", str(REPO)], "log", str(REPO), "--log is deprecated"),
        (["where", "Cup", "--lake", str(REPO)], "log", str(REPO), "--lake is deprecated"),
        (["where", "--log", str(REPO), "Cup"], "log", str(REPO), "--log is deprecated"),
        (["where", "Cup", str(REPO)], "log", str(REPO), ""),
        (["bench", "report", "--homes", "a", "--homes", "b"], "evaluation", ["a", "b"],
         "--homes is deprecated; use --evaluation"),
        (["bench", "report", "--evaluation", "a", "--homes", "b"], "evaluation", ["a", "b"],
         "--homes is deprecated"),
        (["bench", "report", "--evaluation", "a", "--evaluation", "b"], "evaluation", ["a", "b"],
         ""),
        (["bench", "homes", "--homes", "ithor-02,paper"], "homes", ["ithor-02", "paper"], ""),
        (["graph", str(REPO), "--at", "3"], "until", 3, "--at is deprecated; use --until"),
        (["data", "build", "--source", str(REPO), "--home", "a=1,201,301,401", "--ithor",
          "b=2,202,302,402"], "ithor", ["a=1,201,301,401", "b=2,202,302,402"],
         "--home is deprecated; use --ithor"),
        (["graph", str(REPO), "--until", "3"], "until", 3, ""),
        (["search", "Apple", "--start", "kitchen-1"], "target", "Apple", ""),
        (["search", "--target", "Apple", "--start", "kitchen-1"], "target", "Apple",
         "--target is deprecated; use the positional argument TARGET"),
    ],
)  # fmt: skip
def test_every_spelling_parses(
    argv: list[str], attribute: str, value: object, note: str, capsys: pytest.CaptureFixture[str]
) -> None:
    args = build_parser().parse_args(argv)
    assert getattr(args, attribute) == value
    err = capsys.readouterr().err
    assert (note in err) if note else err == ""


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["record", "--out", "x.bag"], "--bag-format is required"),
        (["graph"], "the LOG to read is missing"),
        (["search", "--start", "kitchen-1"], "the TARGET to find is missing"),
        (["search", "Apple", "--target", "Cup", "--start", "kitchen-1"], "given twice"),
        (["where", "Cup", str(REPO), "--log", str(REPO / "docs")], "given twice"),
        (["bench", "homes", "--format", "ros1"], "invalid choice"),
    ],
)
def test_a_command_line_that_breaks_them_is_a_usage_error(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(argv)
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "objsearch: error: " in err and message in err


def _pages() -> list[Path]:
    pages = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
    return [p for p in pages if str(p.relative_to(REPO)) not in REGENERATED]


OLD_SPELLINGS = (
    re.compile(r"--json\b"),
    re.compile(r"record\b.*--format ros"),
    re.compile(r"bench homes\b.*--(scenes|starts) \d"),
    re.compile(r"objsearch (graph|where \S+) --(log|lake)\b"),
    re.compile(r"bench report[^`]*--homes\b"),
    re.compile(r"objsearch graph[^`]*--at\b"),
    re.compile(r"objsearch search[^`]*--target\b"),
)


@pytest.mark.parametrize("page", _pages(), ids=lambda p: p.name)
def test_the_docs_use_the_new_spellings(page: Path) -> None:
    lines = page.read_text(encoding="utf-8").splitlines()
    stale = [line for line in lines if any(p.search(line) for p in OLD_SPELLINGS)]
    assert not stale


class _Terminal(io.StringIO):
    """stderr as a terminal (tqdm draws only on one)."""

    def isatty(self) -> bool:
        return True


GOLDEN = REPO / "tests" / "replay" / "golden" / "sim-wpl-updates"
FOLDER_LAKE = Path(__file__).parent / "events" / "fixtures" / "lake-v1" / "lake"


@pytest.mark.parametrize(
    ("command", "label"),
    [
        (["log", "verify", str(GOLDEN)], "log verify"),
        (["log", "repair", "COPY"], "log repair"),
        (["lake", "add", str(GOLDEN), "--robot", "sim", "--lake", "LAKE"], "lake add"),
        (["lake", "verify", "FILLED"], "lake verify"),
        (["lake", "upgrade", "--lake", "OLD"], "lake upgrade"),
        (["liveview", str(GOLDEN), "--mcap", "MCAP"], "liveview"),
        (["graph", str(GOLDEN)], "graph"),
        (["where", "Cup", str(GOLDEN), "--at", "last"], "where"),
    ],
)
@pytest.mark.parametrize("stderr", ["terminal", "terminal --no-progress", "pipe"])
def test_long_commands_draw_progress_on_a_terminal_only(
    command: list[str], label: str, stderr: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    places = {"LAKE": tmp_path / "lake", "MCAP": tmp_path / "view.mcap", "COPY": tmp_path / "log"}
    if "COPY" in command:
        shutil.copytree(GOLDEN, places["COPY"])
    if "OLD" in command:  # a per-run-folder lake, as the last version that wrote one left it
        places["OLD"] = tmp_path / "old"
        shutil.copytree(FOLDER_LAKE, places["OLD"])
    if "FILLED" in command:
        places["FILLED"] = tmp_path / "filled"
        add = ["lake", "add", str(GOLDEN), "--robot", "sim", "--lake", str(places["FILLED"])]
        monkeypatch.setattr(sys, "stdout", io.StringIO())
        assert main([*add, "--no-progress"]) == 0
    argv = [str(places[w]) if w in places else w for w in command]
    err = _Terminal() if stderr.startswith("terminal") else io.StringIO()
    monkeypatch.setenv("COLUMNS", "100")
    monkeypatch.setattr(sys, "stderr", err)
    monkeypatch.setattr(sys, "stdout", io.StringIO())
    assert main([*argv, *(["--no-progress"] if stderr.endswith("--no-progress") else [])]) == 0
    assert (f"{label}: " in err.getvalue()) is (stderr == "terminal")
    assert "\r" not in err.getvalue() or stderr == "terminal"


@pytest.mark.parametrize("stderr", ["pipe", "pipe --no-progress", "terminal"])
def test_audit_prints_lines_in_a_pipe_and_a_bar_on_a_terminal(
    stderr: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # audit of a long log ran 4¾ minutes saying nothing into a pipe (DEVELOPERS.md: a long
    # command prints a line per unit of work there, as data build and bench dhs do).
    err = _Terminal() if stderr == "terminal" else io.StringIO()
    monkeypatch.setenv("COLUMNS", "100")
    monkeypatch.setattr(sys, "stderr", err)
    monkeypatch.setattr(sys, "stdout", io.StringIO())
    argv = ["audit", str(GOLDEN), "--out", str(tmp_path / "audit")]
    assert main([*argv, *(["--no-progress"] if stderr.endswith("--no-progress") else [])]) == 0
    lines = err.getvalue().splitlines()
    if stderr == "pipe":
        assert re.fullmatch(r"audit: 8 tasks read \(\d+ s\)", lines[0])
        assert lines[1] == f"audit: writing the report of 8 tasks to {tmp_path / 'audit'}"
        assert "\r" not in err.getvalue()
    elif stderr == "terminal":
        assert "audit: " in err.getvalue() and "tasks read" not in err.getvalue()
    else:
        assert err.getvalue() == ""


def test_log_lines_come_every_so_many_and_at_the_end(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    items = list(t.log_lines(range(25), "count", "evens", counts=lambda n: n % 2 == 0, every=5))
    assert items == list(range(25))
    counted = [line.split(" (")[0] for line in err.getvalue().splitlines()]
    assert counted == ["count: 5 evens read", "count: 10 evens read", "count: 13 evens read"]


def test_progress_stays_out_of_a_pipe(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # record and ingest drew their bars into pipes and logs once (a redraw every few seconds).
    piped = io.StringIO()
    monkeypatch.setattr(sys, "stderr", piped)
    monkeypatch.setattr(sys, "stdout", io.StringIO())
    bag = tmp_path / "one.bag"
    record = ["record", "--out", str(bag), "--bag-format", "ros1", "--scenes", "1"]
    assert main([*record, "--targets", "Apple", "--starts", "kitchen-1"]) == 0
    assert main(["ingest", str(bag), "--lake", str(tmp_path / "lake")]) == 0
    assert "\r" not in piped.getvalue() and "it/s" not in piped.getvalue()
