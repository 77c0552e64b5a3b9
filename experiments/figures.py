"""Figures in the docs that a command prints, regenerated from that command and checked against it.

A document marks each such figure as a block::

    <!-- figures:demo -->
    ...generated: the command and the lines of its output that are the figure...
    <!-- /figures -->

:data:`FIGURES` says, per name, the command and which lines of its output are the figure.
``python -m objsearch.experiments.figures [--check] [--only NAME,...] FILE...`` runs the commands
(in one fresh temporary folder, so nothing in the checkout is touched: relative ``out/`` paths
land there, and a figure that reads another's output, such as the demo's log, finds it) and rewrites the blocks, or with ``--check`` exits 1 naming each block
that differs from a fresh run. ``make figures`` and ``make check-figures`` run it over the README
and docs; the test suite checks the cheap ones (``FIGURES[name].cheap``).
"""

from __future__ import annotations

import argparse
import re
import shlex
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from objsearch.agent.errors import ObjsearchError

BLOCK = re.compile(
    r"(?P<open><!-- figures:(?P<name>[a-z0-9-]+) -->\n)(?P<body>.*?)(?P<close><!-- /figures -->)",
    re.DOTALL,
)


@dataclass(frozen=True, slots=True)
class Figure:
    """One command whose output lines matching ``keep`` are a figure in the docs."""

    argv: tuple[str, ...]  # after ``objsearch``
    keep: tuple[str, ...]  # regular expressions; a line of stdout matching one is kept
    cheap: bool  # seconds: checked by the test suite; else only by ``make check-figures``
    needs: tuple[str, ...] = ()  # figures whose commands must run first (their outputs are read)
    #: (pattern, replacement) applied to kept lines: what varies run to run (a timing) goes.
    subs: tuple[tuple[str, str], ...] = ()
    shown_as: str = ""  # how the docs name the command, if not by its argv (e.g. ``make demo``)

    def command(self) -> str:
        return "objsearch " + shlex.join(self.argv)


DEMO = ("demo", "--out", "out/demo", "--force")  # what `make demo` runs

FIGURES: dict[str, Figure] = {
    "demo": Figure(
        DEMO,
        keep=(r"^target  ", r"^mean, ", r"^success rate ", r"^path to discovery ", r"^full path "),
        cheap=True,
        shown_as="make demo",
    ),
    "map-show": Figure(("map", "show"), keep=(r"^agreement with ALFRED ",), cheap=True),
    "map-build": Figure(
        ("map", "build", "--out", "out/map.json"),
        keep=(r"^vs ground truth: ", r"^  missed: ", r"^searches \("),
        cheap=True,
    ),
    # The paper's three strategies (48 s on 2 cores); without --strategies, bench paper runs
    # every registered one (about an hour), so the block is the whole output of this command.
    "bench-paper": Figure(
        ("bench", "paper", "--out", "out/bench-paper", "--strategies", "paper", "--no-progress"),
        keep=(r"^",),
        cheap=False,
        subs=((r" in [0-9.]+ s;", ";"),),
    ),
    "replay": Figure(
        ("replay", "out/demo/log-all"), keep=(r"^\d+ decisions: ",), cheap=True, needs=("demo",)
    ),
    "replay-alpha": Figure(
        ("replay", "out/demo/log-all", "--alpha", "2"),
        keep=(r"^\d+ decisions: ",),
        cheap=True,
        needs=("demo",),
    ),
    "liveview": Figure(
        ("liveview", "out/demo/log-all", "--mcap", "out/live.mcap"),
        keep=(r"^out/live.mcap: ", r"^  /objsearch/live/"),
        cheap=False,
        needs=("demo",),
        subs=((r" in [0-9.]+ s", ""),),
    ),
}


def run_figure(name: str, cwd: Path, done: dict[str, str] | None = None) -> str:
    """The block's body for ``name``: its command run in ``cwd`` (after the figures it needs).
    ``done`` holds the bodies of the figures already run in ``cwd``; each runs once."""
    done = {} if done is None else done
    if name in done:
        return done[name]
    figure = FIGURES[name]
    for need in figure.needs:
        run_figure(need, cwd, done)
    proc = subprocess.run(
        [sys.executable, "-m", "objsearch.cli", *figure.argv],
        cwd=cwd,
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode not in (0, 1):  # replay exits 1 when a decision differs: that is the figure
        raise ObjsearchError(
            f"figure {name}: `{figure.command()}` exited {proc.returncode}: {proc.stderr[-2000:]}"
        )
    patterns = [re.compile(p) for p in figure.keep]
    kept = [line for line in proc.stdout.splitlines() if any(p.search(line) for p in patterns)]
    for pattern, replacement in figure.subs:
        kept = [re.sub(pattern, replacement, line) for line in kept]
    if not kept:
        raise ObjsearchError(f"figure {name}: `{figure.command()}` printed none of its lines")
    shown = f"`{figure.shown_as}` (`{figure.command()}`)" if figure.shown_as else None
    head = shown or f"`{figure.command()}`"
    done[name] = f"{head} prints (generated by `make figures`; do not edit):\n\n```\n"
    done[name] += "\n".join(kept) + "\n```\n"
    return done[name]


def blocks(text: str) -> list[tuple[str, str]]:
    """(name, body) of every figures block in a document, in order."""
    return [(m["name"], m["body"]) for m in BLOCK.finditer(text)]


def replace_blocks(text: str, bodies: dict[str, str]) -> str:
    """``text`` with each named block's body replaced (blocks not in ``bodies`` kept)."""

    def swap(m: re.Match[str]) -> str:
        body = bodies.get(m["name"], m["body"])
        return m["open"] + body + m["close"]

    return BLOCK.sub(swap, text)


def fresh_bodies(
    names: Iterable[str], log: Callable[[str], None] = lambda _m: None
) -> dict[str, str]:
    """Each named figure's body from a fresh run, all in one temporary folder."""
    wanted = sorted(set(names))
    unknown = [n for n in wanted if n not in FIGURES]
    if unknown:
        raise ObjsearchError(
            f"unknown figure(s) {', '.join(unknown)}; known: {', '.join(sorted(FIGURES))}"
        )
    done: dict[str, str] = {}
    with tempfile.TemporaryDirectory(prefix="objsearch-figures-") as tmp:
        for name in wanted:
            log(f"running `{FIGURES[name].command()}` for figure {name}")
            run_figure(name, Path(tmp), done)
    return {name: done[name] for name in wanted}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m objsearch.experiments.figures",
        description="Regenerate (or with --check, compare) the figures blocks of documents.",
    )
    parser.add_argument("files", nargs="+", type=Path, help="documents with figures blocks")
    parser.add_argument("--check", action="store_true", help="compare, do not write (exit 1)")
    parser.add_argument(
        "--only", help="comma-separated figure names (default: every block in the files)"
    )
    parser.add_argument("--cheap", action="store_true", help="only the figures that take seconds")
    args = parser.parse_args(argv)
    try:
        texts = {f: f.read_text(encoding="utf-8") for f in args.files}
        names = {name for text in texts.values() for name, _ in blocks(text)}
        if args.only:
            names &= set(args.only.split(","))
        if args.cheap:
            names = {n for n in names if n in FIGURES and FIGURES[n].cheap}
        bodies = fresh_bodies(names, log=lambda m: print(m, file=sys.stderr))
    except (OSError, ObjsearchError) as exc:
        print(f"objsearch: error: {exc}", file=sys.stderr)
        return 2
    stale = []
    for path in texts:
        # Read again: the runs take minutes and the file may have been edited meanwhile.
        text = path.read_text(encoding="utf-8")
        new = replace_blocks(text, bodies)
        if new == text:
            continue
        if args.check:
            stale += [f"{path}: {n}" for n, b in blocks(text) if n in bodies and bodies[n] != b]
        else:
            path.write_text(new, encoding="utf-8")
            print(f"rewrote {path}")
    if stale:
        print("stale figures (run `make figures`): " + "; ".join(stale), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
