"""How the lake's costs grow with the number of runs: per-run folders against the fleet table.

    python benchmarks/lake_fleet.py [--sizes 10,100,1000,10000] [--folder-sizes 10,100,1000]
                                    [--reps 5] [--log tests/replay/golden/sim-wpl-updates]

One real run (the golden log, 795 events of ten types, committed once) is the template; a lake
of N runs holds N copies of it under other robot / date / run names, made cheaply: the fleet
table gets the template's rows with new run columns, 500 runs a transaction, then is compacted
(:meth:`TableLake.compact`); the per-run-folder lake (``objsearch.lake/1``, the old layout) gets
copies of the template's folder with a rewritten manifest. What is timed, median of ``--reps``:

* **setup**: ``open_analytics`` (what every ``objsearch query`` does before the SQL runs) and
  closing it, per size and layout; the ratio of the largest fleet lake to the smallest
  (target ≤ 2);
* **query**: a typical analyst query over the largest fleet lake through ``open_analytics`` +
  ``run_query``, against plain DuckDB reading the same table (its current files, listed by
  ``deltalake``) in the same run (target ≤ 2×);
* **add**: committing one more run (``add_log`` of the golden log, then removing it) into the
  smallest and the largest fleet lake (target: the same time).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import shutil
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import duckdb
import pyarrow as pa

from objsearch.agent.catalogue import STORE
from objsearch.events.lake import RUN_FILE, Lake, compact_log
from objsearch.events.lake_digest import FILES_KEY, SELF_KEY, manifest_digest
from objsearch.events.lake_table import TableLake, TableRun, add_log, run_parts
from objsearch.events.sql_limits import close
from objsearch.replay.analytics import open_analytics, run_query

QUERY = (
    "SELECT object_class, count(*) AS n, avg(mask_area) AS area FROM detection "
    "WHERE accepted GROUP BY ALL ORDER BY ALL"
)
PLAIN = (
    "SELECT detection.object_class, count(*) AS n, avg(detection.mask_area) AS area "
    "FROM read_parquet($files, union_by_name = true) WHERE detection.accepted GROUP BY ALL ORDER BY ALL"
)
BATCH = 500


def timed(fn: Callable[[], object], reps: int) -> float:
    times = []
    for _ in range(reps):
        started = time.perf_counter()
        fn()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def names(i: int) -> tuple[str, str, str]:
    day = dt.date(2026, 1, 1) + dt.timedelta(days=i % 30)
    return f"robot{i % 10:02d}", day.isoformat(), f"run-{i:05d}"


def build_fleet(root: Path, template: Path, n: int) -> TableLake:
    lake = TableLake(root, store=STORE)
    source = Lake(template, store=STORE)
    info = source.runs()[0]
    tables = source.read_tables(info)
    base = TableRun(info.robot, info.date, info.run, "c", dict(info.rows), info.digest, "bench")
    parts = run_parts(tables, base, STORE)
    pending = []
    for i in range(n):
        robot, day, run = names(i)
        one = TableRun(robot, day, run, f"c{i}", dict(info.rows), info.digest, "bench")
        copies = {}
        for kind, part in parts.items():
            rows = part.num_rows
            values = {
                "robot": pa.array([robot] * rows),
                "date": pa.array([dt.date.fromisoformat(day)] * rows, pa.date32()),
                "run": pa.array([run] * rows),
                "commit": pa.array([one.commit] * rows),
            }
            copy = part
            for name, column in values.items():
                index = copy.schema.get_field_index(name)
                copy = copy.set_column(index, copy.schema.field(name), column)
            copies[kind] = copy
        pending.append((one, copies))
        if len(pending) == BATCH:
            lake.commit_many(pending)
            pending = []
    lake.commit_many(pending)
    lake.compact(vacuum_hours=0)
    return lake


def build_folders(root: Path, template: Path, n: int) -> None:
    source = Lake(template, store=STORE).runs()[0]
    for i in range(n):
        robot, day, run = names(i)
        target = root / f"robot={robot}" / f"date={day}" / f"run={run}"
        shutil.copytree(source.path, target)
        doc = json.loads((target / RUN_FILE).read_bytes())
        doc.update(robot=robot, date=day, run=run)
        doc.pop(SELF_KEY)
        doc[SELF_KEY] = manifest_digest(doc)
        assert FILES_KEY in doc
        (target / RUN_FILE).write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")


def setup_time(lake: Path, reps: int) -> float:
    return timed(lambda: close(open_analytics(lake)), reps)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--sizes", default="10,100,1000,10000")
    ap.add_argument("--folder-sizes", default="10,100,1000")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--log", default="tests/replay/golden/sim-wpl-updates")
    ap.add_argument("--extra-log", default="tests/replay/golden/sim-rvp-targets")
    args = ap.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    folder_sizes = [int(s) for s in args.folder_sizes.split(",") if s]
    work = Path(tempfile.mkdtemp(prefix="objsearch-bench-lake-fleet-"))
    print(
        f"lake growth, {args.reps} reps, medians; command: python benchmarks/lake_fleet.py "
        + " ".join(sys.argv[1:])
    )
    try:
        template = work / "template"
        compact_log(Path(args.log), Lake(template, store=STORE), robot="t")
        print(f"{'runs':>7} {'layout':>14} {'build s':>9} {'files':>7} {'setup s':>9}")
        folder_setup = {}
        for n in folder_sizes:
            root = work / f"folders-{n}"
            started = time.perf_counter()
            build_folders(root, template, n)
            built = time.perf_counter() - started
            files = sum(1 for _ in root.rglob("*.parquet"))
            folder_setup[n] = setup_time(root, args.reps)
            print(f"{n:>7} {'per-run folder':>14} {built:>9.1f} {files:>7} {folder_setup[n]:>9.3f}")
        fleet_setup = {}
        lakes = {}
        for n in sizes:
            root = work / f"fleet-{n}"
            started = time.perf_counter()
            lakes[n] = build_fleet(root, template, n)
            built = time.perf_counter() - started
            files = len(lakes[n].data_files())
            fleet_setup[n] = setup_time(root, args.reps)
            print(f"{n:>7} {'fleet table':>14} {built:>9.1f} {files:>7} {fleet_setup[n]:>9.3f}")
        lo, hi = min(sizes), max(sizes)
        print(
            f"setup, fleet table: {hi} runs / {lo} runs = {fleet_setup[hi] / fleet_setup[lo]:.2f} (target ≤ 2)"
        )
        if len(folder_sizes) > 1:
            a, b = min(folder_sizes), max(folder_sizes)
            print(
                f"setup, per-run folders: {b} runs / {a} runs = {folder_setup[b] / folder_setup[a]:.2f}"
            )

        big = work / f"fleet-{hi}"

        def ours() -> object:
            con = open_analytics(big)
            try:
                return run_query(con, QUERY)[1]
            finally:
                close(con)

        def plain() -> object:
            from deltalake import DeltaTable

            files = DeltaTable(str(big / "events")).file_uris(
                file_pruning_predicate=[("type", "=", "detection")]
            )
            return duckdb.connect().execute(PLAIN, {"files": files}).fetchall()

        assert ours() == plain(), "objsearch query and plain DuckDB disagree"
        t_ours, t_plain = timed(ours, args.reps), timed(plain, args.reps)
        print(f"query over {hi} runs ({QUERY!r}):")
        print(
            f"  objsearch (open_analytics + run_query) {t_ours:.3f} s, plain DuckDB on the "
            f"table's files {t_plain:.3f} s, ratio {t_ours / t_plain:.2f} (target ≤ 2)"
        )

        extra = Path(args.extra_log)
        adds = {}
        for n in (lo, hi):
            lake = lakes[n]

            def add(lake: TableLake = lake) -> None:
                info = add_log(extra, lake, robot="extra", run="extra")
                lake.remove_run(info.robot, info.run)

            adds[n] = timed(add, args.reps)
        print(
            f"lake add (+ remove) of one run: {lo} runs {adds[lo]:.3f} s, {hi} runs "
            f"{adds[hi]:.3f} s, ratio {adds[hi] / adds[lo]:.2f}"
        )
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
