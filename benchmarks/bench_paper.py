"""The full paper benchmark (Table I with 20 SDP seeds, RVP, WPL; long-term with no / target / all
updates) in parallel processes, against the same work in one process measured in the same run.

Target (issue 3): under 2 minutes on a 2-core machine. Prints medians over --repeat runs and the
ratio. Usage: .venv/bin/python benchmarks/bench_paper.py [--repeat N] [--strategies paper|all]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

from objsearch.experiments.paper import run_paper
from objsearch.experiments.strategies import PAPER_STRATEGIES, STRATEGIES

TARGET_S = 120.0


def timed(workers: int, strategies: list[str]) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        run_paper(Path(tmp), strategies=strategies, workers=workers, progress=False)
        return time.perf_counter() - start


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--strategies", default="paper", choices=["paper", "all"])
    args = parser.parse_args()
    strategies = list(PAPER_STRATEGIES if args.strategies == "paper" else STRATEGIES)
    serial = [timed(1, strategies) for _ in range(args.repeat)]
    parallel = [timed(2, strategies) for _ in range(args.repeat)]
    s, p = statistics.median(serial), statistics.median(parallel)
    print(
        f"bench paper ({args.strategies} strategies): 1 process {s:.1f} s, 2 processes {p:.1f} s, "
        f"speed-up ×{s / p:.2f}; target < {TARGET_S:.0f} s: {'met' if p < TARGET_S else 'MISSED'}"
    )
    return 0 if p < TARGET_S else 1


if __name__ == "__main__":
    sys.exit(main())
