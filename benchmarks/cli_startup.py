"""What a command costs before it does anything: CPU time of ``objsearch --help`` and of one
search, against a bare interpreter, all measured in the same run.

    python benchmarks/cli_startup.py [--reps 7]

Each command runs ``--reps`` times as a fresh process (``sys.executable -m objsearch.cli``, the
console script's own entry); its CPU time is the child's user + system time
(``resource.getrusage(RUSAGE_CHILDREN)``), which a busy machine inflates far less than wall
time. Baselines in the same run: ``python -c pass`` and ``python -c 'import argparse'`` (what any
command line pays). Medians and ratios are printed. Targets (issue 22): ``--help`` ≤ 0.3
CPU-s, one search ≤ 2× ``--help``.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path

CLI = (sys.executable, "-m", "objsearch.cli")


def cpu_seconds(argv: Sequence[str]) -> float:
    """User + system CPU time of one run of ``argv`` (which must succeed)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--reps", type=int, default=7, help="runs of each command (7)")
    args = parser.parse_args()
    if args.reps < 1:
        parser.error("--reps must be at least 1")
    with tempfile.TemporaryDirectory(prefix="objsearch-startup-") as tmp:
        search = [
            *CLI,
            "search",
            "Apple",
            "--start",
            "kitchen-1",
            "--format",
            "json",
            "--log",
            str(Path(tmp) / "log"),
        ]
        commands = {
            "python -c pass": [sys.executable, "-c", "pass"],
            "python -c 'import argparse'": [sys.executable, "-c", "import argparse"],
            "objsearch --help": [*CLI, "--help"],
            "objsearch search (one search)": search,
        }
        times: dict[str, list[float]] = {name: [] for name in commands}
        for _ in range(args.reps):  # interleaved, so a burst of load hits every command alike
            for name, argv in commands.items():
                times[name].append(cpu_seconds(argv))
    medians = {name: statistics.median(t) for name, t in times.items()}
    load = os.getloadavg()[0]
    print(f"# CLI start-up, CPU seconds (user + sys), median of {args.reps}; load {load:.1f}")
    print(f"{'command':34} {'median':>8} {'min':>8} {'max':>8}")
    for name, t in times.items():
        print(f"{name:34} {medians[name]:8.3f} {min(t):8.3f} {max(t):8.3f}")
    help_s = medians["objsearch --help"]
    search_s = medians["objsearch search (one search)"]
    bare = medians["python -c 'import argparse'"]
    print(f"--help / python -c 'import argparse': {help_s / bare:.1f}×")
    print(f"--help: {help_s:.3f} CPU-s (target ≤ 0.3) {'ok' if help_s <= 0.3 else 'MISSED'}")
    print(
        f"one search / --help: {search_s / help_s:.2f}× (target ≤ 2) "
        f"{'ok' if search_s <= 2 * help_s else 'MISSED'}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
