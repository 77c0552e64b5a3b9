"""The lake-bookkeeping battery at size: every edit of every kind to a fleet lake's table log and
its runs' records, every answer checked.

    python benchmarks/lake_log_damage.py [--per-kind N] [--seed 21]

Builds the battery's fleet lake (three runs made with the real CLI, one ``lake add`` each) and a
compacted copy, then for every kind of :mod:`devtools.lake_log_battery` (each ``add``, ``txn``
and ``commitInfo`` line of each commit removed, each ``add`` duplicated; each commit deleted,
copied as the next version, cut at each kind of place, bit-flipped; the newest commit deleted;
each ``_run`` file deleted, cut, flipped, replaced; the head record deleted or garbled) tries
every target the kind has on each lake (or ``--per-kind`` picked at random), asking each copy
``query``, ``lake ls``, ``lake verify``, ``lake compact`` then ``query``, ``lake add`` then
``query``. Prints, per kind and in total: tried / clear error / unchanged / traceback / silent
change / loss (see the module), lists every variant in the last three columns, and exits 1 if
there is any.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

# devtools/ (the harnesses, not installed) is a folder of the checkout, beside this one's.
sys.path.insert(1, str(Path(__file__).resolve().parents[1]))

from devtools.lake_log_battery import COLUMNS, KINDS, build, run_battery


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument(
        "--per-kind", type=int, default=None, help="variants per kind (default: every target)"
    )
    ap.add_argument("--seed", type=int, default=21)
    args = ap.parse_args()
    if args.per_kind is not None and args.per_kind < 1:
        ap.error("--per-kind must be at least 1")
    work = Path(tempfile.mkdtemp(prefix="objsearch-bench-lake-log-damage-"))
    started = time.perf_counter()
    try:
        lakes, log = build(work / "built")
        report = run_battery(lakes, log, work / "battery", per_kind=args.per_kind, seed=args.seed)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    seconds = time.perf_counter() - started
    every = "every target" if args.per_kind is None else f"{args.per_kind} per kind"
    print(f"lake-bookkeeping battery, seed {args.seed}, {every}, on the lake and compacted")
    print(f"  command: python benchmarks/lake_log_damage.py {' '.join(sys.argv[1:])}".rstrip())
    print(f"  {report.tried} damaged lakes, {len(KINDS)} kinds")
    print(f"  {'kind':38} {'tried':>6} " + " ".join(f"{c:>13}" for c in COLUMNS))
    total = {c: report.counts[c] for c in COLUMNS}
    for name, row in [*report.by_kind.items(), ("total", {"tried": report.tried, **total})]:
        print(f"  {name:38} {row['tried']:6} " + " ".join(f"{row[c]:13}" for c in COLUMNS))
    print(f"  ({seconds:.0f} s, {1000 * seconds / max(1, report.tried):.0f} ms per damaged lake)")
    for line in report.flagged:
        print(f"  FLAGGED {line}")
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main())
