"""Peak memory and time of ``objsearch lake add`` of one long log: per-run-folder lake against
the fleet lake (streamed commit), in the same run.

    python benchmarks/lake_add_memory.py [--events 1000000] [--reps 1]

Writes a closed log of ``--events`` synthetic events (``benchmarks/events.py: synthetic_run``:
detections, moves, task starts and ends), then runs ``objsearch lake add`` on it in a fresh
process per layout, and prints each one's wall time and peak RSS (of that
process: the interpreter, the imports and the commit; ``VmHWM``, not ``ru_maxrss``, which on
Linux starts from the forking parent's size). Target: ≤ 300 MB for 1 M events.
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
from objsearch.agent.catalogue import STORE
from objsearch.events.lake_table import TableLake

PROBE = """
import logging, sys
logging.basicConfig(level=logging.WARNING)
logging.getLogger("objsearch.events.lake_table").setLevel(logging.INFO)
from objsearch.cli import main
rc = main(sys.argv[1:])
# VmHWM: this process image's peak. Not ru_maxrss: Linux carries the peak of the image before
# exec over, and a forked child's starts at its parent's (this benchmark holds the events).
hwm = next(l for l in open("/proc/self/status") if l.startswith("VmHWM:")).split()[1]
print("MAXRSS_KB", hwm, file=sys.stderr)
sys.exit(rc)
"""


def lake_add(log: Path, lake: Path) -> tuple[float, float]:
    started = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", PROBE, "lake", "add", str(log), "--robot", "r", "--lake", str(lake)],
        capture_output=True,
        text=True,
    )
    seconds = time.perf_counter() - started
    if done.returncode != 0:
        raise SystemExit(f"lake add failed: {done.stderr}")
    for line in done.stderr.splitlines():
        if "need more" in line:
            print("   ", line)
    kb = next(int(line.split()[1]) for line in done.stderr.splitlines() if "MAXRSS_KB" in line)
    return seconds, kb / 1024


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--events", type=int, default=1_000_000)
    ap.add_argument("--reps", type=int, default=1)
    ap.add_argument("--layouts", default="per-run folders,fleet table")
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
        for layout in args.layouts.split(","):
            times, peaks = [], []
            for rep in range(args.reps):
                lake = work / f"lake-{layout[:3]}-{rep}"
                if layout == "fleet table":
                    TableLake(lake, store=STORE).create()
                seconds, mb = lake_add(log, lake)
                times.append(seconds)
                peaks.append(mb)
                shutil.rmtree(lake)
            results[layout] = (statistics.median(times), max(peaks))
            print(
                f"  {layout:16} {results[layout][0]:7.1f} s  peak RSS {results[layout][1]:7.0f} MB"
            )
        if len(results) < 2:
            return 0
        base, fleet = results["per-run folders"], results["fleet table"]
        print(
            f"  fleet / folders: time {fleet[0] / base[0]:.2f}, peak RSS {fleet[1] / base[1]:.2f}"
            f" (target: ≤ 300 MB)"
        )
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
