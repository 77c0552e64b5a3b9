"""Exact WPL planning: subset DP against brute-force enumeration on the same random instances.

    python benchmarks/planner.py [--reps 5] [--seed 0]

For n = 6…10 both solve the same instances (medians of --reps runs, their ratio, and a check that
both reach the same optimum); for n = 11…16 the DP runs alone. Times are medians, since the machine
is shared and noisy.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from typing import TypeVar

import numpy as np

from objsearch.agent.planner import wpl_enumerate, wpl_exact

T = TypeVar("T")


def instance(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    pts = rng.uniform(0, 8, size=(n + 1, 2))
    d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    return d[0, 1:], d[1:, 1:], rng.uniform(0, 1, size=n)


def timed(fn: Callable[..., T], *args: object) -> tuple[float, T]:
    t0 = time.perf_counter()
    out = fn(*args)
    return time.perf_counter() - t0, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-enum", type=int, default=10, help="largest n for enumeration")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    print(f"{'n':>3} {'DP median s':>12} {'enum median s':>14} {'enum/DP':>9}  same optimum")
    for n in range(6, 17):
        dp_times, enum_times, same = [], [], True
        for _ in range(args.reps if n <= args.max_enum else max(1, args.reps // 2)):
            start, dist, rel = instance(n, rng)
            t_dp, dp = timed(wpl_exact, start, dist, rel, 10.0)
            dp_times.append(t_dp)
            if n <= args.max_enum:
                t_en, en = timed(wpl_enumerate, start, dist, rel, 10.0)
                enum_times.append(t_en)
                same &= abs(dp.value - en.value) <= 1e-9 * max(1.0, en.value)
        dp_med = statistics.median(dp_times)
        if enum_times:
            en_med = statistics.median(enum_times)
            print(f"{n:>3} {dp_med:12.5f} {en_med:14.4f} {en_med / dp_med:9.1f}  {same}")
            if not same:
                raise SystemExit(f"DP and enumeration disagree at n = {n}")
        else:
            print(f"{n:>3} {dp_med:12.5f} {'-':>14} {'-':>9}")


if __name__ == "__main__":
    main()
