"""Peak memory and time of ``objsearch lake add`` of one long log into the fleet lake (streamed
commit), against the baseline of reading that log alone, in the same run.

    python benchmarks/lake_add_memory.py [--events 1000000] [--reps 1]

Writes a closed log of ``--events`` synthetic events (``benchmarks/events.py: synthetic_run``:
detections, moves, task starts and ends), then, in a fresh process each: reads every event of
it (``read_log`` with the add's imports loaded: the floor of any add), and runs ``objsearch lake add``
on it; prints each one's wall time and peak RSS (of that process: the interpreter, the imports
and the work; ``VmHWM``, not ``ru_maxrss``, which on Linux starts from the forking parent's
size). Target: ≤ 300 MB for 1 M events. (Until the fleet lake became the default the baseline
was ``lake add`` into the per-run-folder lake, which this version no longer writes: 1,341 MB
for 1 M events, docs/analytics.md.)
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from events import _write_log, synthetic_run

PROBE = """
import logging, sys
logging.basicConfig(level=logging.WARNING)
logging.getLogger("objsearch.events.lake").setLevel(logging.INFO)
from objsearch.cli import main
rc = main(sys.argv[1:])
# VmHWM: this process image's peak. Not ru_maxrss: Linux carries the peak of the image before
# exec over, and a forked child's starts at its parent's (this benchmark holds the events).
hwm = next(l for l in open("/proc/self/status") if l.startswith("VmHWM:")).split()[1]
print("MAXRSS_KB", hwm, file=sys.stderr)
sys.exit(rc)
"""


READ = """
import sys
import duckdb, deltalake  # the add's imports: the CLI, the fleet lake and what it reads with
import objsearch.cli, objsearch.events.lake
from objsearch.events import read_log
from objsearch.product import STORE
n = sum(1 for _ in read_log(sys.argv[1], store=STORE))
hwm = next(l for l in open("/proc/self/status") if l.startswith("VmHWM:")).split()[1]
print("MAXRSS_KB", hwm, file=sys.stderr)
"""


def measured(code: str, *argv: str) -> tuple[float, float]:
    """Wall time and peak RSS (MB) of ``python -c code argv…`` in a fresh process."""
    started = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", code, *argv],
        capture_output=True,
        text=True,
    )
    seconds = time.perf_counter() - started
    if done.returncode != 0:
        raise SystemExit(f"{argv[0]} failed: {done.stderr}")
    for line in done.stderr.splitlines():
        if "need more" in line:
            print("   ", line)
    kb = next(int(line.split()[1]) for line in done.stderr.splitlines() if "MAXRSS_KB" in line)
    return seconds, kb / 1024


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--events", type=int, default=1_000_000)
    ap.add_argument("--reps", type=int, default=1)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="objsearch-bench-lake-add-"))
    try:
        log = work / "log"
        _write_log(log, synthetic_run(args.events))
        size = (log / "events.log").stat().st_size
        print(
            f"lake add of one log: {args.events:,} events, {size / 1e6:.0f} MB; {args.reps} rep(s)"
        )
        print("  command: python benchmarks/lake_add_memory.py " + " ".join(sys.argv[1:]))
        results = {}
        for what in ("read the log (baseline)", "lake add"):
            times, peaks = [], []
            for rep in range(args.reps):
                lake = work / f"lake-{rep}"
                if what == "lake add":
                    argv = ["lake", "add", str(log), "--robot", "r", "--lake", str(lake)]
                    seconds, mb = measured(PROBE, *argv)
                    shutil.rmtree(lake)
                else:
                    seconds, mb = measured(READ, str(log))
                times.append(seconds)
                peaks.append(mb)
            results[what] = (statistics.median(times), max(peaks))
            print(f"  {what:26} {results[what][0]:7.1f} s  peak RSS {results[what][1]:7.0f} MB")
        base, add = results["read the log (baseline)"], results["lake add"]
        print(
            f"  lake add / reading the log: time {add[0] / base[0]:.2f}, peak RSS "
            f"{add[1] / base[1]:.2f}; lake add peak RSS {add[1]:.0f} MB (target: ≤ 300 MB)"
        )
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
