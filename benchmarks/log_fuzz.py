"""The event-log fuzzer at benchmark size: ≥ 10,000 seeded mutations of a real log.

    python benchmarks/log_fuzz.py                 # 10,000 cases, seed 0
    python benchmarks/log_fuzz.py --cases 50000 --seed 7

Prints how the next writer met each damaged log (refused with an error / opened unchanged /
torn fragment cut and kept aside / the two cases undetectable by design / traceback / silent
change), per mutation, and the time per case. Exit status 1 if any case crashed the writer or
changed a fact without an error. The suite runs the same harness with 2,000 cases
(tests/events/test_logfuzz.py).
"""

from __future__ import annotations

import argparse
import sys
import time

from objsearch.events.logfuzz import run_log_fuzz


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--events", type=int, default=30, help="events in each base log (30)")
    args = parser.parse_args()
    if args.cases < 1 or args.events < 6:
        parser.error("--cases must be >= 1 and --events >= 6")
    start = time.perf_counter()
    report = run_log_fuzz(args.cases, seed=args.seed, events=args.events)
    elapsed = time.perf_counter() - start
    print(f"log fuzz, seed {args.seed}, {args.events}-event logs: {report.summary()}")
    for key, count in sorted(report.by_mutation.items()):
        print(f"  {key:45} {count:6d}")
    print(f"{elapsed:.1f} s ({1000 * elapsed / report.tried:.2f} ms per case)")
    for failure in report.failures[:20]:
        print("FAILURE", failure)
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main())
