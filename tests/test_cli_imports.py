"""The command line imports what a command uses and nothing else: ``objsearch --help`` loads no
numerical or storage library, and options whose choices need one are still there when their
command runs (``cli_types.Parser.defer``)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from objsearch.cli import build_parser, main

#: Each costs a noticeable share of a second to import; none is needed to list the commands.
#: (msgspec is not among them: the event type is a msgspec Struct, and it imports in ~10 ms.)
HEAVY = (
    "numpy",
    "networkx",
    "torch",
    "polars",
    "duckdb",
    "pyarrow",
    "jsonschema",
    "cv2",
)


def _loaded_after(argv: list[str]) -> set[str]:
    code = (
        "import sys\n"
        "from objsearch.cli import main\n"
        f"code = main({argv!r})\n"
        "print(' '.join(sorted({m.split('.')[0] for m in sys.modules})))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    return set(out.split())


def test_help_loads_no_heavy_library() -> None:
    assert _loaded_after(["--help"]) & set(HEAVY) == set()


def test_a_commands_help_loads_none_of_what_its_options_do_not_need() -> None:
    assert _loaded_after(["log", "--help"]) & set(HEAVY) == set()
    assert _loaded_after(["query", "--help"]) & {"networkx", "torch", "numpy"} == set()


@pytest.mark.parametrize(
    ("words", "options"),
    [
        (["search"], ["--strategy", "--camera", "--home", "--alpha"]),
        (["demo"], ["--strategy", "--camera"]),
        (["bench", "paper"], ["--prior", "--camera"]),
        (["agent", "run"], ["--strategy", "--live-max-clients", "--live-client-queue"]),
        (["record"], ["--camera"]),
    ],
)
def test_deferred_options_are_there_when_the_command_runs(
    words: list[str], options: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([*words, "--help"]) == 0
    shown = capsys.readouterr().out
    for option in options:
        assert option in shown, option
    # and parsed: a bad choice is refused by the command's own parser
    assert main([*words, options[0], "no-such-choice"]) == 2
    assert "objsearch: error:" in capsys.readouterr().err


def test_version_is_looked_up_only_when_asked(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.startswith("objsearch ")


def test_build_parser_still_builds_every_option_for_a_walk() -> None:
    parser = build_parser()
    assert parser.parse_args(["search", "Apple", "--start", "kitchen-1"]).strategy
