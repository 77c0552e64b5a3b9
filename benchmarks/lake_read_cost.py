"""CPU time and peak memory of ``where`` and ``replay`` from a fleet-lake run, against the same
command on the log the run was added from, measured in the same run.

    python benchmarks/lake_read_cost.py [--events 1000000] [--reps 3]

Writes a closed log of ``--events`` synthetic events (``benchmarks/events.py: synthetic_run``),
adds it to a fresh fleet lake (``objsearch lake add``), then ``--reps`` times, each command in a
fresh process, the log's first and the lake's right after it: ``objsearch where Apple LOG`` and
``objsearch where Apple LAKE --run bench``, ``objsearch replay LOG`` and ``objsearch replay LAKE
--run bench``. Prints each one's CPU seconds (user + system of that process) and peak RSS
(``VmHWM``: the interpreter, the imports and the work), their medians, and the ratios lake / log
(of the medians, and the median of each rep's pair). Target (issue 43): ≤ 1.5x the CPU and
≤ 2x the memory.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from events import _write_log, synthetic_run

PROBE = """
import resource, sys
from objsearch.cli import main
rc = main(sys.argv[1:])
usage = resource.getrusage(resource.RUSAGE_SELF)
# VmHWM: this process image's peak (ru_maxrss carries the forking parent's over on Linux).
hwm = next(l for l in open("/proc/self/status") if l.startswith("VmHWM:")).split()[1]
print("PROBE", usage.ru_utime + usage.ru_stime, hwm, file=sys.stderr)
sys.exit(rc)
"""


def measured(*argv: str) -> tuple[float, float]:
    """CPU seconds and peak RSS (MB) of ``objsearch argv…`` in a fresh process."""
    done = subprocess.run(
        [sys.executable, "-c", PROBE, *argv], capture_output=True, text=True, check=False
    )
    if done.returncode not in (0, 1):
        raise SystemExit(f"objsearch {' '.join(argv)} failed: {done.stderr[-2000:]}")
    line = next(x for x in done.stderr.splitlines() if x.startswith("PROBE "))
    _, cpu, kb = line.split()
    return float(cpu), int(kb) / 1024


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--events", type=int, default=1_000_000)
    ap.add_argument("--reps", type=int, default=3)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="objsearch-bench-lake-read-"))
    try:
        log, lake = work / "log", work / "lake"
        _write_log(log, synthetic_run(args.events))
        add = ["lake", "add", str(log), "--robot", "r", "--lake", str(lake), "--no-progress"]
        measured(*add)
        commands = {
            "where": (["where", "Apple"], ["--no-progress"]),
            "replay": (["replay"], ["--no-progress"]),
        }
        print(f"where / replay from a lake run vs its log: {args.events} events, {args.reps} reps")
        print(f"  command: python benchmarks/lake_read_cost.py {' '.join(sys.argv[1:])}".rstrip())
        print(f"  load average at start: {_load()}")
        ok = True
        for name, (head, tail) in commands.items():
            runs: dict[str, list[tuple[float, float]]] = {"log": [], "lake": []}
            for _ in range(args.reps):
                runs["log"].append(measured(*head, str(log), *tail))
                runs["lake"].append(measured(*head, str(lake), "--run", "bench", *tail))
            print(f"\n  {name}")
            for source, got in runs.items():
                cpu = ", ".join(f"{c:.2f}" for c, _ in got)
                mem = ", ".join(f"{m:.0f}" for _, m in got)
                print(f"    {source:4}  CPU-s {cpu}  (median {statistics.median(c for c, _ in got):.2f});"
                      f"  peak MB {mem}  (median {statistics.median(m for _, m in got):.0f})")  # fmt: skip
            cpu_ratio = statistics.median(c for c, _ in runs["lake"]) / statistics.median(
                c for c, _ in runs["log"]
            )
            mem_ratio = statistics.median(m for _, m in runs["lake"]) / statistics.median(
                m for _, m in runs["log"]
            )
            pairs = list(zip(runs["lake"], runs["log"], strict=True))
            cpu_pairs = statistics.median(a[0] / b[0] for a, b in pairs)
            mem_pairs = statistics.median(a[1] / b[1] for a, b in pairs)
            print(f"    lake / log: CPU {cpu_ratio:.2f}x (pairs' median {cpu_pairs:.2f}x; target "
                  f"<= 1.5x), memory {mem_ratio:.2f}x (pairs' median {mem_pairs:.2f}x; target <= 2x)")  # fmt: skip
            ok = ok and cpu_ratio <= 1.5 and mem_ratio <= 2.0
        print(f"\n  load average at end: {_load()} (the machine may be shared: compare the pairs)")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
