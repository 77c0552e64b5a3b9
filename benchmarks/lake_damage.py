"""The lake-damage battery at size: ≥ 200 damaged files, every answer checked.

    python benchmarks/lake_damage.py [--per-kind 14] [--seed 21]

Builds a lake of three runs with the real CLI from the bundled data (``objsearch search`` per
target, ``objsearch lake add``), then for every kind of damage of
:mod:`objsearch.lake_battery` (bit flips in data pages, in the footer, anywhere; random bytes;
cuts; zeroed ranges; garbage appended; files deleted; files swapped between runs or copied from
another run; valid Parquet with one value changed; a table added; manifests flipped, cut or
deleted; run folders swapped) makes ``--per-kind`` copies of the lake, each with one damage, and
asks each copy ``objsearch query`` (every row of every view) and ``objsearch lake verify``.
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

from objsearch.fleet_battery import FLEET_KINDS, build_fleet_lake, run_fleet_battery
from objsearch.lake_battery import COLUMNS, KINDS, build_lake, run_battery


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--per-kind", type=int, default=14, help="variants per kind of damage (14)")
    ap.add_argument("--seed", type=int, default=21)
    ap.add_argument(
        "--without-digests",
        action="store_true",
        help="the control: the same damage on a lake whose manifests have no digests (as older "
        "code wrote them), to show what the digests catch",
    )
    ap.add_argument(
        "--fleet",
        action="store_true",
        help="the battery on the fleet lake (objsearch.fleet_battery): the same lake's runs, one "
        "lake add each, damaged in its data files and its table's log",
    )
    args = ap.parse_args()
    if args.per_kind < 1:
        ap.error("--per-kind must be at least 1")
    work = Path(tempfile.mkdtemp(prefix="objsearch-bench-lake-damage-"))
    started = time.perf_counter()
    try:
        if args.fleet:
            fleet = build_fleet_lake(work / "built")
            report = run_fleet_battery(
                fleet, work / "battery", per_kind=args.per_kind, seed=args.seed
            )
            kinds = list(FLEET_KINDS)
        else:
            kinds = list(KINDS)
            lake = build_lake(work / "built")
            report = run_battery(
                lake,
                work / "battery",
                per_kind=args.per_kind,
                seed=args.seed,
                without_digests=args.without_digests,
            )
    finally:
        shutil.rmtree(work, ignore_errors=True)
    seconds = time.perf_counter() - started
    control = ", CONTROL: manifests without digests" if args.without_digests else ""
    print(f"lake-damage battery, seed {args.seed}, {args.per_kind} per kind of damage{control}")
    print(f"  command: python benchmarks/lake_damage.py {' '.join(sys.argv[1:])}".rstrip())
    print(f"  {report.tried} damaged lakes, {report.files} damaged files, {len(kinds)} kinds")
    print(f"  {'kind':34} {'tried':>6} " + " ".join(f"{c:>13}" for c in COLUMNS))
    total = {c: report.counts[c] for c in COLUMNS}
    for name, row in [*report.by_kind.items(), ("total", {"tried": report.tried, **total})]:
        print(f"  {name:34} {row['tried']:6} " + " ".join(f"{row[c]:13}" for c in COLUMNS))
    print(f"  ({seconds:.0f} s, {1000 * seconds / max(1, report.tried):.0f} ms per damaged lake)")
    for line in report.flagged[: 20 if args.without_digests else None]:
        print(f"  FLAGGED {line}")
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main())
