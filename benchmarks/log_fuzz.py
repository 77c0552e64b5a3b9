"""The event-log batteries at benchmark size: seeded damage to real logs and snapshots.

    python benchmarks/log_fuzz.py                 # 10,000 writer cases, seed 0, and the rest
    python benchmarks/log_fuzz.py --cases 50000 --seed 7
    python benchmarks/log_fuzz.py --only battery --battery-events 300

Five batteries, each printed as tried / clear error / unchanged / traceback / silent change /
loss (the last three must be 0; exit status 1 otherwise), and, for the two that repair, the
intact records moved out:

- **writer**: the next writer opens each damaged log and appends (refused with an error / opened
  unchanged; the cases undetectable by design are counted apart);
- **restart**: the same, opened as an agent restarting from a snapshot does (``verify="sealed"``:
  the prefix checked by its seals) — it must refuse whatever the full check refuses;
- **repair**: ``objsearch log repair`` on damaged 300-event logs, then a verify and an append:
  nothing neither kept nor quarantined (loss), no kept event that is not the one written, no
  removed seq or id reused; also how many repairs moved intact records out, by mutation;
- **snapshot**: attested snapshots damaged every way, restored: always the log's fold, a
  rejected one said in one log line;
- **battery**: every kind of line damage (blank, duplicated, swapped, moved, deleted, cut,
  split lines; bits flipped in a record, its checksum, tab or newline; garbage, another log's
  line, CR LF, edited values) at every line of a closed and a crashed log, and every edit of
  ``meta.json``, through ``objsearch log repair`` (:mod:`devtools.repair_battery`):
  no intact record may be moved out (exit status 1 otherwise).

The suite runs smaller versions of each (tests/events/test_logfuzz.py).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

# devtools/ (the harnesses, not installed) is a folder of the checkout, beside this one's.
sys.path.insert(1, str(Path(__file__).resolve().parents[1]))

from devtools.logfuzz import run_log_fuzz, run_repair_fuzz, run_snapshot_fuzz
from devtools.repair_battery import run_repair_battery

HEADER = (
    f"{'battery':9} {'tried':>7} {'clear error':>12} {'unchanged':>10} {'traceback':>10} "
    f"{'silent change':>14} {'loss':>5} {'intact moved out':>17}"
)
BATTERIES = ("writer", "restart", "repair", "snapshot", "battery")


def row(
    name: str,
    tried: int,
    error: int,
    same: int,
    tb: int,
    silent: int,
    loss: int,
    moved: int | None = None,
) -> str:
    last = "-" if moved is None else str(moved)
    return f"{name:9} {tried:7d} {error:12d} {same:10d} {tb:10d} {silent:14d} {loss:5d} {last:>17}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=10_000, help="writer cases (10,000)")
    parser.add_argument("--repairs", type=int, default=2_000, help="repair cases (2,000)")
    parser.add_argument("--snapshots", type=int, default=1_000, help="snapshot cases (1,000)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--events", type=int, default=30, help="events in each writer log (30)")
    parser.add_argument(
        "--battery-events", type=int, default=120, help="events in the battery's logs (120)"
    )
    parser.add_argument(
        "--battery-stride", type=int, default=1, help="damage every Nth line in the battery (1)"
    )
    parser.add_argument(
        "--only", choices=BATTERIES, action="append", help="run only these batteries (repeatable)"
    )
    args = parser.parse_args()
    if (
        min(args.cases, args.repairs, args.snapshots, args.battery_stride) < 1
        or min(args.events, args.battery_events) < 6
    ):
        parser.error(
            "--cases, --repairs, --snapshots and --battery-stride must be >= 1, --events and "
            "--battery-events >= 6"
        )
    only = set(args.only or BATTERIES)
    rows, failures, ok = [], [], True
    for name, verify in (("writer", "all"), ("restart", "sealed")):
        if name not in only:
            continue
        start = time.perf_counter()
        report = run_log_fuzz(args.cases, seed=args.seed, events=args.events, verify=verify)
        print(f"{name}: {report.summary()} ({time.perf_counter() - start:.1f} s)")
        for key, count in sorted(report.by_mutation.items()):
            print(f"  {key:45} {count:6d}")
        # undetectable by design (a clean prefix past the mark, a forgery past it): unchanged
        same = report.unchanged + report.torn_kept + report.clean_prefix + report.forged
        rows.append(
            row(name, report.tried, report.refused, same, report.traceback, report.silent_change, 0)
        )
        failures += report.failures
        ok &= report.ok
    if "repair" in only:
        ok &= _repair(args, rows, failures)
    if "snapshot" in only:
        ok &= _snapshot(args, rows, failures)
    if "battery" in only:
        ok &= _battery(args, rows, failures)
    print()
    print(HEADER)
    print("\n".join(rows))
    for failure in failures[:20]:
        print("FAILURE", failure)
    return 0 if ok else 1


def _repair(args: argparse.Namespace, rows: list[str], failures: list[str]) -> bool:
    start = time.perf_counter()
    repair = run_repair_fuzz(args.repairs, seed=args.seed, events=300)
    print(f"repair (300-event logs): {repair.summary()} ({time.perf_counter() - start:.1f} s)")
    for key, count in sorted(repair.by_mutation.items()):
        print(f"  {key:45} {count:6d}")
    print(
        "  repairs that moved ≥ 1 intact record out, by mutation:", dict(repair.moved_by_mutation)
    )
    rows.append(
        row(
            "repair",
            repair.tried,
            repair.clear_error,
            repair.unchanged + repair.repaired + repair.forged,
            repair.traceback,
            repair.silent_change,
            repair.loss,
            sum(repair.intact_moved_out),
        )
    )
    failures += repair.failures
    return repair.ok


def _snapshot(args: argparse.Namespace, rows: list[str], failures: list[str]) -> bool:
    start = time.perf_counter()
    snaps = run_snapshot_fuzz(args.snapshots, seed=args.seed)
    print(f"snapshot: {snaps.summary()} ({time.perf_counter() - start:.1f} s)")
    rows.append(
        row(
            "snapshot",
            snaps.tried,
            snaps.rebuilt,
            snaps.unchanged,
            snaps.traceback,
            snaps.silent_change,
            0,
        )
    )
    failures += snaps.failures
    return snaps.ok


def _battery(args: argparse.Namespace, rows: list[str], failures: list[str]) -> bool:
    start = time.perf_counter()
    report = run_repair_battery(args.battery_events, stride=args.battery_stride)
    stride = args.battery_stride
    where = "every line" if stride == 1 else f"every {stride}th line"
    print(
        f"battery ({args.battery_events}-event logs, damage at {where}): "
        f"{report.summary()} ({time.perf_counter() - start:.1f} s)"
    )
    print(f"  {'damage':32} {'cases':>6} {'intact moved out':>17}")
    for kind, (cases, moved) in sorted(report.by_kind.items()):
        print(f"  {kind:32} {cases:6d} {moved:17d}")
    rows.append(
        row(
            "battery",
            report.tried,
            report.clear_error,
            report.unchanged + report.repaired,
            report.traceback,
            report.silent_change,
            report.loss,
            report.intact_moved_out,
        )
    )
    failures += report.failures
    return report.ok


if __name__ == "__main__":
    sys.exit(main())
