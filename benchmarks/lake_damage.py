"""The lake-damage battery at size: ≥ 200 damaged files, every answer checked.

    python benchmarks/lake_damage.py [--per-kind 14] [--seed 21]

Builds a fleet lake of three runs with the real CLI from the bundled data (``objsearch search``
per target, one ``objsearch lake add`` a run), then for every kind of damage of
:mod:`devtools.lake_battery` (bit flips in data pages, in the footer, anywhere; random bytes;
cuts; zeroed ranges; garbage appended; data files deleted; valid Parquet with one value changed;
commit files of the table's log flipped, cut or deleted) makes ``--per-kind`` copies of the lake,
each with one damage, and asks each copy ``objsearch query`` (every row of every view) and
``objsearch lake verify``.
Prints, per kind and in total: tried / clear error / unchanged / traceback / silent change /
loss (see the module for what each means), lists every variant in the last three columns, and
exits 1 if there is any.
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

from devtools.lake_battery import COLUMNS, KINDS, build_lake, run_battery


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--per-kind", type=int, default=14, help="variants per kind of damage (14)")
    ap.add_argument("--seed", type=int, default=21)
    args = ap.parse_args()
    if args.per_kind < 1:
        ap.error("--per-kind must be at least 1")
    work = Path(tempfile.mkdtemp(prefix="objsearch-bench-lake-damage-"))
    started = time.perf_counter()
    try:
        lake = build_lake(work / "built")
        report = run_battery(lake, work / "battery", per_kind=args.per_kind, seed=args.seed)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    seconds = time.perf_counter() - started
    print(f"lake-damage battery, seed {args.seed}, {args.per_kind} per kind of damage")
    print(f"  command: python benchmarks/lake_damage.py {' '.join(sys.argv[1:])}".rstrip())
    print(f"  {report.tried} damaged lakes, {report.files} damaged files, {len(KINDS)} kinds")
    print(f"  {'kind':34} {'tried':>6} " + " ".join(f"{c:>13}" for c in COLUMNS))
    total = {c: report.counts[c] for c in COLUMNS}
    for name, row in [*report.by_kind.items(), ("total", {"tried": report.tried, **total})]:
        print(f"  {name:34} {row['tried']:6} " + " ".join(f"{row[c]:13}" for c in COLUMNS))
    print(f"  ({seconds:.0f} s, {1000 * seconds / max(1, report.tried):.0f} ms per damaged lake)")
    for line in report.flagged:
        print(f"  FLAGGED {line}")
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main())
