"""The bad-input battery at full size: every subcommand, every option, every malformed value.

    python benchmarks/bad_inputs.py [--processes N] [--timeout S]

Three parts, each printing tried / clear error / traceback / other:

* **options**: every argument of every subcommand (walked from the parser, so new ones are
  covered) with each malformed value of ``devtools.cli_battery`` plus a few more, run in-process
  through ``objsearch.cli.main``; the cases the option's type rejects must be clear errors;
* **processes**: one malformed value per argument again, each in its own ``python -m
  objsearch.cli`` (``--processes`` caps how many; 0 runs all), half of them on an ASCII-only
  terminal (``PYTHONIOENCODING=ascii``);
* **semantic**: values every option type accepts but the data does not (an unknown home, target,
  strategy or schedule; a text file given as a bag, a log, a topic map, a model or a robot.toml;
  an empty folder as a log, lake or data source), each in its own process.

``clear error`` is exit 2 with ``objsearch: error:`` on stderr; ``traceback`` is a Python
traceback; ``other`` is anything else (listed). The run fails (exit 1) unless every case is a
clear error.
"""

from __future__ import annotations

import argparse
import collections
import sys
import tempfile
import time
from collections.abc import Iterable
from pathlib import Path

# devtools/ (the harnesses, not installed) is a folder of the checkout, beside this one's.
sys.path.insert(1, str(Path(__file__).resolve().parents[1]))

from devtools import cli_battery as battery
from objsearch.cli import build_parser

#: More malformed values for the in-process part (hex, underscores, signs, other digits, a name
#: too long for the file system). Not "--opt=--": Python 3.11's argparse reads it as no value.
MORE = ("0x10", "1_000_000_000_000", "+inf", "-0.0", "1e-400", "١٢", "ŝ", "x" * 5000)


def semantic_cases(scratch: Path) -> list[tuple[str, list[str]]]:
    """Command lines whose every value parses but names something that is not there or wrong."""
    text, empty = str(scratch / battery.FILE), str(scratch / battery.DIR)
    topics = scratch / "topics.toml"
    topics.write_text("this is = = not toml\n", encoding="utf-8")
    config = scratch / "robot.toml"
    config.write_text("[zenoh]\nlisten = 'tcp/1.2.3.4:1'\nmode = 7\n", encoding="utf-8")
    bag = scratch / "fake.bag"
    bag.write_bytes(b"#ROSBAG V2.0\n" + b"\0" * 64)
    search = ["search", "Apple", "--start", "kitchen-1"]
    return [
        ("unknown target", ["search", "Spaceship", "--start", "kitchen-1"]),
        ("static target", ["search", "Fridge", "--start", "kitchen-1"]),
        ("unknown start", ["search", "Apple", "--start", "garage-3"]),
        ("unknown home", [*search, "--home", "castle"]),
        ("unknown schedule", [*search, "--scene", "2", "--schedule", "weekly"]),
        ("bad seeded schedule", [*search, "--scene", "2", "--schedule", "stats-x"]),
        ("log is an empty folder", ["graph", "--log", empty]),
        ("seq past the log", ["graph", "--log", empty, "--at", "5"]),
        ("demo in an unknown home", ["demo", "--out", str(scratch / "demo"), "--home", "castle"]),
        ("demo into someone's folder", ["demo", "--out", str(scratch), "--force"]),
        ("record unknown format", ["record", "--out", str(scratch / "r"), "--bag-format", "ros3"]),
        (
            "record unknown target",
            ["record", "--out", str(scratch / "r.bag"), "--bag-format", "ros1", "--targets", "Cat"],
        ),
        (
            "record bad topic map",
            ["record", "--out", str(scratch / "r.bag"), "--bag-format", "ros1", "--topics", text],
        ),
        (
            "record topic map not toml",
            [
                "record",
                *("--out", str(scratch / "r.bag"), "--bag-format", "ros1", "--topics", str(topics)),
            ],
        ),
        ("ingest a text file", ["ingest", text, "--lake", str(scratch / "lake")]),
        ("ingest a fake bag", ["ingest", str(bag), "--lake", str(scratch / "lake")]),
        ("ingest an empty folder", ["ingest", empty, "--lake", str(scratch / "lake")]),
        ("query without a lake", ["query", "SELECT 1", "--lake", str(scratch / "nolake")]),
        ("query bad SQL", ["query", "SELEKT", "--lake", empty]),
        ("lake add an empty folder", ["lake", "add", empty, "--robot", "r", "--lake", empty]),
        ("lake ls of a file", ["lake", "ls", "--lake", text]),
        ("replay an empty folder", ["replay", empty]),
        ("replay unknown strategy", ["replay", empty, "--strategy", "magic"]),
        ("audit an empty folder", ["audit", empty, "--out", str(scratch / "audit")]),
        ("liveview an empty folder", ["liveview", empty, "--mcap", str(scratch / "v.mcap")]),
        ("liveview not .mcap", ["liveview", empty, "--mcap", str(scratch / "v.txt")]),
        ("map show unknown home", ["map", "show", "--home", "castle"]),
        ("map build from a text bag", ["map", "build", "--bag", text, "--no-search"]),
        ("map build bad model", ["map", "build", "--model", text, "--no-search"]),
        ("bench unknown strategy", ["bench", "paper", "--strategies", "magic"]),
        ("bench unknown target", ["bench", "paper", "--targets", "Cat", "--strategies", "wpl"]),
        ("bench unknown home", ["bench", "homes", "--homes", "castle"]),
        ("bench unknown schedule kind", ["bench", "homes", "--schedules", "weekly"]),
        ("bench report of nothing", ["bench", "report", "--paper", empty, "--evaluation", empty]),
        ("data build from nothing", ["data", "build", "--source", empty, "--out", str(scratch)]),
        ("data build bad home", ["data", "build", "--source", empty, "--ithor", "x=1,2"]),
        ("agent run bad config", ["agent", "run", "--log", str(scratch / "l"), "--config", text]),
        (
            "agent run config with bad values",
            ["agent", "run", "--log", str(scratch / "l"), "--config", str(config)],
        ),
        ("robot sim unknown schedule", ["robot", "sim", "--schedule", "weekly", "--scene", "2"]),
    ]


def _tally(
    name: str, outcomes: Iterable[tuple[str, battery.BatteryOutcome]], seconds: float
) -> int:
    counts: collections.Counter[str] = collections.Counter()
    shown = []
    for label, outcome in outcomes:
        counts[outcome.verdict] += 1
        if outcome.verdict != "clear error":
            shown.append(
                f"    {outcome.verdict}: {label}: exit {outcome.code}: "
                f"{outcome.stderr.strip().splitlines()[-1:]}"
            )
    tried = sum(counts.values())
    print(
        f"{name:10} tried {tried:5}  clear error {counts['clear error']:5}  "
        f"traceback {counts['traceback']:3}  other {counts['other']:3}   ({seconds:.1f} s)"
    )
    for line in shown[:20]:
        print(line)
    return tried - counts["clear error"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--processes", type=int, default=60, help="real-process cases (0: all)")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per process (120)")
    args = ap.parse_args(argv)
    parser = build_parser()
    bad = 0
    with tempfile.TemporaryDirectory(prefix="objsearch-bad-inputs-") as tmp:
        scratch = battery.prepare(Path(tmp))
        cases = list(battery.cases(parser, scratch, extra=MORE))
        invalid = [c for c in cases if c.invalid]
        print(
            f"{len({c.command for c in cases})} subcommands, "
            f"{len({(c.command, c.option) for c in cases})} arguments, {len(cases)} command lines "
            f"({len(cases) - len(invalid)} with values the option accepts, not run here)"
        )
        started = time.perf_counter()
        in_process = [
            (" ".join(c.argv), battery.run_in_process(c.argv, guard=parser)) for c in invalid
        ]
        bad += _tally("options", in_process, time.perf_counter() - started)

        one_each = list({(c.command, c.option): c for c in invalid}.values())
        if args.processes:
            one_each = one_each[:: max(1, len(one_each) // args.processes)][: args.processes]
        started = time.perf_counter()
        real = []
        for i, case in enumerate(one_each):
            env = {"PYTHONIOENCODING": "ascii"} if i % 2 else None
            real.append(
                (
                    " ".join(case.argv),
                    battery.run_subprocess(case.argv, cwd=scratch, env=env, timeout=args.timeout),
                )
            )
        bad += _tally("processes", real, time.perf_counter() - started)

        started = time.perf_counter()
        semantic = [
            (label, battery.run_subprocess(argv, cwd=scratch, timeout=args.timeout))
            for label, argv in semantic_cases(scratch)
        ]
        bad += _tally("semantic", semantic, time.perf_counter() - started)
    print("command: python benchmarks/bad_inputs.py " + " ".join(argv or sys.argv[1:]))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
