"""Run time of the occluding search camera against the geometric one, measured in the same run.

    python benchmarks/camera.py [--repeat 3] [--workload paper,homes]

Each workload is one ``objsearch bench`` command run once per camera, alternating (occluding,
geometric, occluding, ...) so a machine that drifts slows both alike, each in a fresh process (the
visibility caches live in the process: a second run in the same one would find its views cached).
Prints each camera's median wall time, the per-pair ratios and their median; the target (issue 14)
is occluding ≤ 2× geometric. Exit 1 when a median ratio misses it.

Workloads: ``paper`` is ``bench paper`` as shipped (Table I with 20 SDP seeds, Table II's
schedules); ``homes`` is a protocol-v2-shaped ``bench homes`` (docs/results-memory.md): two
evaluation homes, one iTHOR and one ProcTHOR, habit and stats schedules of 10 scenes, 2 start points
per target, the strategies the protocol compares.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_RATIO = 2.0
CAMERAS = ("occluding", "geometric")
WORKLOADS: dict[str, list[str]] = {
    "paper": ["bench", "paper", "--no-progress"],
    "homes": [
        "bench",
        "homes",
        "--no-progress",
        "--homes",
        "ithor-02,procthor-02",
        "--schedules",
        "habit,stats",
        "--seeds",
        "1",
        "--scenes-per-schedule",
        "10",
        "--starts-per-scene",
        "2",
        "--strategies",
        "wpl,ecost,ecost-memory,dist-oracle",
    ],
}


def objsearch() -> str:
    """The ``objsearch`` entry point beside this interpreter (the venv's)."""
    found = Path(sys.executable).with_name("objsearch")
    if not found.exists():
        raise SystemExit(f"no objsearch beside {sys.executable}: run from the project's venv")
    return str(found)


def timed(argv: list[str], camera: str) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        command = [objsearch(), *argv, "--out", str(Path(tmp) / "out"), "--camera", camera]
        start = time.perf_counter()
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
        return time.perf_counter() - start


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per camera (3)")
    parser.add_argument(
        "--workload", default="paper,homes", help=f"comma-separated: {', '.join(WORKLOADS)}"
    )
    args = parser.parse_args()
    names = [w for w in args.workload.split(",") if w]
    unknown = sorted(set(names) - set(WORKLOADS))
    if unknown or args.repeat < 1:
        parser.error(f"unknown workload(s) {unknown}" if unknown else "--repeat must be ≥ 1")
    missed = False
    for name in names:
        times: dict[str, list[float]] = {c: [] for c in CAMERAS}
        for i in range(args.repeat):
            for camera in CAMERAS:
                times[camera].append(timed(WORKLOADS[name], camera))
                print(f"{name} run {i + 1} {camera}: {times[camera][-1]:.1f} s", flush=True)
        ratios = [o / g for o, g in zip(times["occluding"], times["geometric"], strict=True)]
        ratio = statistics.median(ratios)
        missed |= ratio > TARGET_RATIO
        print(
            f"{name}: occluding median {statistics.median(times['occluding']):.1f} s "
            f"(min {min(times['occluding']):.1f}, max {max(times['occluding']):.1f}), geometric "
            f"median {statistics.median(times['geometric']):.1f} s (min "
            f"{min(times['geometric']):.1f}, max {max(times['geometric']):.1f}); occluding/geometric "
            f"per pair {', '.join(f'{r:.2f}' for r in ratios)}, median ×{ratio:.2f}; target "
            f"≤ ×{TARGET_RATIO:.0f}: {'met' if ratio <= TARGET_RATIO else 'MISSED'}",
            flush=True,
        )
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
