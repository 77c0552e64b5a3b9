"""The bad-input battery: every option of every subcommand with malformed values.

The subcommands come from walking the parser :func:`objsearch.cli.build_parser` builds, so a new
subcommand or option is covered without editing anything here. Each :class:`BatteryCase` is one command
line that fills the other required arguments with valid values and gives one option a malformed
one; a case is *expected to fail* when the option's ``type`` (or its ``choices``) rejects the
value. ``tests/test_cli_bad_inputs.py`` runs the battery in-process in CI and
``benchmarks/bad_inputs.py`` runs a larger one, partly in real processes, and prints the counts.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import subprocess
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from devtools.cli_process import run_cli
from objsearch import cli_types

#: Tried on every option: empty, blank, non-numeric, negative, NaN, infinities, huge, fractional.
COMMON = ("", " ", "abc", "-1", "nan", "inf", "-inf", "1e400", "99999999999999", "1.5", "0")
#: Tried on every option besides COMMON (paths are made under the scratch folder).
EXTRA = ("a\nb", "garbage", "tcp/", "host:99999", "[::1", "2026-13-45", ",")
#: The scratch folder's layout: a file, a folder, a path that does not exist, one under a file.
FILE, DIR, MISSING, UNDER_FILE = "a-file.txt", "a-folder", "missing/nowhere", "a-file.txt/sub"


@dataclass(frozen=True, slots=True)
class BatteryCase:
    command: tuple[str, ...]
    option: str
    value: str
    argv: tuple[str, ...]
    #: The option's type or choices reject the value: the CLI must say so (exit 2).
    invalid: bool


@dataclass(frozen=True, slots=True)
class BatteryOutcome:
    code: int
    stdout: str
    stderr: str

    @property
    def verdict(self) -> str:
        """``clear error``, ``traceback`` or ``other`` (anything else: accepted, or unclear)."""
        if "Traceback (most recent call last)" in self.stderr:
            return "traceback"
        if self.code == 2 and "objsearch: error: " in self.stderr:
            return "clear error"
        return "other"


def prepare(scratch: Path) -> Path:
    """Make the scratch folder the battery's paths point into."""
    scratch.mkdir(parents=True, exist_ok=True)
    (scratch / FILE).write_text("not what was asked for\n", encoding="utf-8")
    (scratch / DIR).mkdir(exist_ok=True)
    return scratch


def leaf_parsers(
    parser: argparse.ArgumentParser, path: tuple[str, ...] = ()
) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """Every runnable subcommand (a parser without subcommands of its own) and its words, each
    with its deferred arguments added."""
    if isinstance(parser, cli_types.Parser):
        parser.build_deferred()
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield path, parser
        return
    for action in subs:
        for name, child in action.choices.items():
            yield from leaf_parsers(child, (*path, name))


def value_actions(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """The arguments that take a value (not --help, not flags)."""
    return [
        a
        for a in parser._actions
        if a.nargs != 0 and not isinstance(a, argparse._SubParsersAction | argparse._HelpAction)
    ]


def action_name(action: argparse.Action) -> str:
    """The name argparse's messages give the argument (``--workers``, ``BAG``, ``sql``)."""
    if action.option_strings:
        return "/".join(action.option_strings)
    if isinstance(action.metavar, str):
        return action.metavar
    return action.dest


def accepts(action: argparse.Action, value: str) -> bool:
    """Whether the argument's own checks (type, choices) let ``value`` through."""
    converted: object = value
    if callable(action.type):
        try:
            converted = action.type(value)
        except (argparse.ArgumentTypeError, TypeError, ValueError):
            return False
    return action.choices is None or converted in action.choices


def _valid_value(action: argparse.Action, scratch: Path) -> str:
    if action.choices is not None:
        return str(next(iter(action.choices)))
    candidates = (
        "1",
        "x.bag",
        str(scratch / DIR),
        str(scratch / FILE),
        str(scratch / "new-output"),
        "SELECT 1",
        "2026-01-01",
        "tcp/127.0.0.1:7447",
    )
    for value in candidates:
        if accepts(action, value):
            return value
    raise AssertionError(f"no valid sample value for {action_name(action)}")


def _argv(action: argparse.Action, value: str) -> list[str]:
    if action.option_strings:
        return [f"{action.option_strings[0]}={value}"]
    return [value]


def malformed_values(scratch: Path, extra: Sequence[str] = ()) -> list[str]:
    paths = [str(scratch / p) for p in (FILE, DIR, MISSING, UNDER_FILE)]
    return [*COMMON, *EXTRA, *paths, *extra]


def cases(
    parser: argparse.ArgumentParser, scratch: Path, extra: Sequence[str] = ()
) -> Iterator[BatteryCase]:
    """One case per subcommand, argument and malformed value."""
    values = malformed_values(scratch, extra)
    for words, leaf in leaf_parsers(parser):
        actions = value_actions(leaf)
        required = [a for a in actions if a.required or not a.option_strings]
        for action in actions:
            others: list[str] = []
            positionals: list[str] = []
            for other in required:
                if other is action:
                    continue
                if other.option_strings:
                    others += _argv(other, _valid_value(other, scratch))
                else:
                    positionals.append(_valid_value(other, scratch))
            for value in values:
                if action.option_strings:
                    argv = [*words, *others, *_argv(action, value), "--", *positionals]
                else:
                    # Positionals go after "--" so that "-1" or "" are read as values.
                    ordered = [
                        value if a is action else _valid_value(a, scratch)
                        for a in required
                        if not a.option_strings
                    ]
                    argv = [*words, *others, "--", *ordered]
                if argv[-1] == "--":
                    argv.pop()
                yield BatteryCase(
                    words, action_name(action), value, tuple(argv), not accepts(action, value)
                )


def run_in_process(
    argv: Sequence[str],
    *,
    guard: argparse.ArgumentParser | None = None,
    parser: argparse.ArgumentParser | None = None,
) -> BatteryOutcome:
    """``objsearch.cli.main(argv)`` with its output captured; a traceback is caught and kept.

    With ``guard`` (a parser from ``build_parser``) a command line that parses is not run but
    reported as ``other``: a malformed value that got through must not start a real search,
    bench or server inside the battery. One that does not parse is run by ``main`` with that
    same parser, not a new one per case (building the whole command tree was all of a case's
    time: 14 ms against well under 1 ms for the parse). ``parser``: a parser from
    ``build_parser`` that runs the command, as the kill-test server keeps one for all its
    commands (the defaults it read from the environment are those of when it was built)."""
    import traceback

    from objsearch.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        if guard is not None:
            try:
                guard.parse_args(list(argv))
            except SystemExit:
                pass
            else:
                return BatteryOutcome(0, "", "the command line parsed; not run")
        try:
            code = main(list(argv), parser=guard or parser)
        except BaseException:
            traceback.print_exc(file=err)
            code = 1
    return BatteryOutcome(code, out.getvalue(), err.getvalue())


def run_subprocess(
    argv: Sequence[str], *, cwd: Path, env: dict[str, str] | None = None, timeout: float = 120
) -> BatteryOutcome:
    """``python -m objsearch.cli ARGV`` in its own process (a timeout counts as ``other``)."""
    try:
        proc = run_cli(*argv, env=env, cwd=cwd, timeout=timeout)
    except subprocess.TimeoutExpired:
        return BatteryOutcome(-1, "", f"timed out after {timeout} s")
    return BatteryOutcome(proc.returncode, proc.stdout, proc.stderr)


def unvalidated(parser: argparse.ArgumentParser) -> list[str]:
    """Arguments whose value nothing checks: neither a type from :mod:`objsearch.cli_types`
    nor a fixed set of choices."""
    return [
        f"{' '.join(words)} {action_name(a)}"
        for words, leaf in leaf_parsers(parser)
        for a in value_actions(leaf)
        if a.choices is None and not cli_types.is_validated(a.type)
    ]
