"""The damaged-bag battery at size: many seeded variants per format, and the shared real bags.

    python benchmarks/damaged_bags.py [--per-kind 12] [--seed 12] [--no-real]

Records one simulated run per format (scene 1, targets Apple and Cup, start kitchen-1, odometry
at 10 Hz, ROS 1 chunks of 16 KiB so a bag has several), takes the real bags of
``../shared/data/bags`` as they are, and for each bag makes ``--per-kind`` variants of every kind
of damage that applies (:mod:`devtools.bag_battery`: cuts, bit flips, 4 KiB zeroed
inside a chunk, and the renames: no ``metadata.yaml``, a wrong extension). Every variant is
ingested by ``objsearch ingest`` into a fresh lake and checked against the intact bag's ingest,
per topic. Prints, per format and in total: tried / exit 0 complete / exit 0 with the loss
reported / exit 2 with a clear error / traceback / silent loss / over-reported, and lists every
variant in the last three columns.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

# devtools/ (the harnesses, not installed) is a folder of the checkout, beside this one's.
sys.path.insert(1, str(Path(__file__).resolve().parents[1]))

from devtools.bag_battery import account, ingest_cli, variants
from objsearch.cli import main as cli_main
from objsearch.pipeline.bags.formats import BagFormat, detect
from objsearch.pipeline.bags.record import record

COLUMNS = ("complete", "loss-reported", "error", "traceback", "silent-loss", "over-reported")
SHARED_BAGS = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "bags"


def real_bags() -> list[Path]:
    if not SHARED_BAGS.is_dir():
        return []
    bags = sorted(SHARED_BAGS.glob("*/*.bag"))
    bags += sorted(p for p in SHARED_BAGS.glob("rosbag2/*") if p.is_dir())
    return bags


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--per-kind", type=int, default=12, help="variants per kind of damage")
    ap.add_argument("--seed", type=int, default=12)
    ap.add_argument("--no-real", action="store_true", help="only the recorded bags")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="objsearch-bench-damaged-"))
    started = time.perf_counter()
    try:
        bags: list[tuple[str, Path]] = []
        for fmt in BagFormat:
            name = "run.bag" if fmt is BagFormat.ROS1 else "run"
            rec = record(
                work / fmt.value / name,
                fmt,
                scenes=[1],
                targets=["Apple", "Cup"],
                starts=["kitchen-1"],
                odom_hz=10.0,
                chunk_bytes=16 * 1024,
            )
            bags.append((f"recorded {fmt.value}", rec.path))
        if not args.no_real:
            bags += [(f"real {p.relative_to(SHARED_BAGS)}", p) for p in real_bags()]
        table: dict[str, Counter[str]] = {}
        flagged: list[str] = []
        for label, bag in bags:
            fmt = detect(bag)
            intact = ingest_cli(bag, work / "intact" / label.replace("/", "_"), cli_main)
            if intact.code != 0 or account(intact, intact).outcome != "complete":
                flagged.append(f"{label}: the intact bag does not ingest cleanly: {intact.stderr}")
                continue
            row = table.setdefault(fmt.value, Counter())
            for i, v in enumerate(variants(bag, fmt, args.seed, args.per_kind)):
                where = work / "v" / f"{i}"
                damaged = v.make(where / "bag")
                verdict = account(intact, ingest_cli(damaged, where / "lake", cli_main))
                row["tried"] += 1
                row[verdict.outcome] += 1
                if verdict.outcome in ("traceback", "silent-loss", "over-reported"):
                    flagged.append(
                        f"{label} {v.name}: {verdict.outcome}: {'; '.join(verdict.problems)[:400]}"
                    )
                shutil.rmtree(where)
        total: Counter[str] = Counter()
        for row in table.values():
            total.update(row)
        print(f"damaged-bag battery, seed {args.seed}, {args.per_kind} per kind of damage")
        print(f"  command: python benchmarks/damaged_bags.py {' '.join(sys.argv[1:])}".rstrip())
        print(f"  bags: {', '.join(label for label, _ in bags)}")
        header = f"  {'format':14} {'tried':>6} " + " ".join(f"{c:>14}" for c in COLUMNS)
        print(header)
        for name, row in [*sorted(table.items()), ("total", total)]:
            print(f"  {name:14} {row['tried']:6} " + " ".join(f"{row[c]:14}" for c in COLUMNS))
        print(f"  ({time.perf_counter() - started:.0f} s)")
        for line in flagged:
            print(f"  FLAGGED {line}")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
