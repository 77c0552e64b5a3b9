"""How the fleet lake's costs grow with the number of runs.

    python benchmarks/lake_fleet.py [--sizes 10,100,1000,10000] [--reps 5]
                                    [--log tests/replay/golden/sim-wpl-updates]

One real run (the golden log, 795 events of ten types, added once) is the template; a lake of N
runs holds N copies of it under other robot / date / run names, made cheaply: the fleet table
gets the template's rows with new run columns, 500 runs a transaction, then is compacted
(:meth:`TableLake.compact`). (The per-run-folder lake this was once compared with is read only by
``lake upgrade`` now; its figures, measured before, are in docs/analytics.md.) What is timed,
median of ``--reps``:

* **setup**: ``open_analytics`` (what every ``objsearch query`` does before the SQL runs) and
  closing it, per size; the ratio of the largest fleet lake to the smallest
  (target ≤ 2); with the fleet lake's verification cache warm (the files hashed by an earlier
  query, what a machine that queries the lake gets), and emptied before each (every data file
  hashed: a machine's first query, or the first after the files changed);
* **query**: a typical analyst query over the largest fleet lake as ``objsearch query`` runs it
  (``open_analytics(lake, for_sql=…)``, which makes only the views the query reads, +
  ``run_query``), and with every view made (``open_analytics(lake)``, what a notebook gets),
  against plain DuckDB reading the same table (the ``deltalake`` table loaded, its current
  files listed, one ``read_parquet``) in the same run (target ≤ 2×);
* **add**: committing one more run (what ``objsearch lake add`` does: the bag sessions asked
  whether they hold the log, then ``add_log`` of a log of ``--add-events`` synthetic events,
  a new log and run name each time) into the smallest and the largest fleet lake, alternating
  between them (target: the same time);
* **ingest's "already there?"**: one recorded bag ingested into the smallest and the largest
  fleet lake, then asked about as ``objsearch ingest`` asks (``FleetBagLake.pieces_known``: the
  bag's stamps in the table's log) against the baseline, what ingest did before
  (``known_pieces``: every ``_run`` row and bag record read), and the whole ``ingest`` of
  the bag again (hash, ask, nothing to read or commit), alternating between the two lakes
  (target: the same time); and what part of it is opening the table (``DeltaTable``: its
  log, application transactions included), which every command pays.
"""

from __future__ import annotations

import argparse
import datetime as dt
import math
import os
import shutil
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import duckdb
import pyarrow as pa
from lake_writers import write_logs

from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake, TableRun, add_log
from objsearch.events.lake.schema import run_parts
from objsearch.events.sql_limits import close
from objsearch.pipeline.bags.formats import BagFormat
from objsearch.pipeline.bags.identity import bag_identity
from objsearch.pipeline.bags.ingest import ingest
from objsearch.pipeline.bags.lake import FleetBagLake, refuse_a_log_a_session_holds
from objsearch.pipeline.bags.record import record
from objsearch.pipeline.bags.session import converter_key
from objsearch.replay.analytics import open_analytics, run_query
from objsearch.ros.topics import TopicMap

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
    source = TableLake(template, store=STORE)
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


def same(a: object, b: object) -> bool:
    """Equal rows, floats to 1e-9 (a parallel sum of doubles may differ in its last bits)."""
    assert isinstance(a, list) and isinstance(b, list)
    return len(a) == len(b) and all(
        len(x) == len(y)
        and all(
            math.isclose(u, v, rel_tol=1e-9) if isinstance(u, float) else u == v
            for u, v in zip(x, y, strict=True)
        )
        for x, y in zip(a, b, strict=True)
    )


def timed_pair(a: Callable[[], object], b: Callable[[], object], reps: int) -> tuple[float, float]:
    """Medians of ``a`` and ``b`` run in turn (so a change in the machine's load hits both)."""
    ta, tb = [], []
    for _ in range(reps):
        ta.append(timed(a, 1))
        tb.append(timed(b, 1))
    return statistics.median(ta), statistics.median(tb)


def setup_time(lake: Path, reps: int) -> float:
    return timed(lambda: close(open_analytics(lake)), reps)


def already_there(work: Path, small: TableLake, large: TableLake, reps: int) -> None:
    """Ingest's question "is this bag in the lake already?" on a small and a large lake."""
    bag = work / "one.bag"
    record(bag, BagFormat.ROS1, scenes=[1], targets=["Apple"], starts=["kitchen-1"], odom_hz=1.0)
    bag_id, key = bag_identity(bag)[0], converter_key(TopicMap())
    roots = {}
    for lake in (small, large):
        [done] = ingest([bag], str(lake.root), robot="bags")
        assert done.error is None and not done.already, done
        roots[len(lake.runs())] = str(lake.root)
    lo, hi = sorted(roots)
    for root in roots.values():
        assert FleetBagLake(root).pieces_known([bag_id], key) == {bag_id: key}
        assert FleetBagLake(root).known_pieces() == {bag_id: key}

    def asked(root: str) -> Callable[[], object]:
        return lambda: FleetBagLake(root).pieces_known([bag_id], key)

    def listed(root: str) -> Callable[[], object]:
        return lambda: FleetBagLake(root).known_pieces()

    def opened(root: str) -> Callable[[], object]:
        return lambda: TableLake(root, store=STORE).table()

    def again(root: str) -> Callable[[], object]:
        def one() -> object:
            [result] = ingest([bag], root, robot="bags")
            assert result.already and result.error is None
            return result

        return one

    print(f'ingest\'s "already there?" for one bag, fleet table of {lo} runs against {hi}:')
    for label, fn in (
        ("stamps in the log (pieces_known, now)", asked),
        ("every record read (known_pieces, before)", listed),
        ("ingest of the bag again (hash + ask)", again),
        ("of which: the table opened (every command does)", opened),
    ):
        t_lo, t_hi = timed_pair(fn(roots[lo]), fn(roots[hi]), reps)
        print(
            f"  {label}: {lo} runs {t_lo:.4f} s, {hi} runs {t_hi:.4f} s, ratio "
            f"{t_hi / t_lo:.2f}" + (" (target: flat)" if "now" in label else "")
        )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--sizes", default="10,100,1000,10000")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--log", default="tests/replay/golden/sim-wpl-updates")
    ap.add_argument("--add-events", type=int, default=1000)
    args = ap.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    work = Path(tempfile.mkdtemp(prefix="objsearch-bench-lake-fleet-"))
    # The fleet lake's verification cache (which data files this machine hashed) in the work
    # folder: emptied for the cold-cache rows, never the user's.
    cache = work / "cache"
    os.environ["OBJSEARCH_CACHE"] = str(cache)
    print(
        f"lake growth, {args.reps} reps, medians; command: python benchmarks/lake_fleet.py "
        + " ".join(sys.argv[1:])
    )
    try:
        template = work / "template"
        add_log(Path(args.log), TableLake(template, store=STORE), robot="t")
        print(f"{'runs':>7} {'layout':>14} {'build s':>9} {'files':>7} {'setup s':>9}")
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
            f"setup (every view), fleet table: {hi} runs / {lo} runs = "
            f"{fleet_setup[hi] / fleet_setup[lo]:.2f}"
        )
        # The two ends again, in turn (a change in load hits both), as `objsearch query` opens
        # the lake for the query below (only its views) and with every view.
        for label, sql in (("objsearch query's", QUERY), ("every view", None)):

            def opened(n: int, sql: str | None = sql) -> Callable[[], object]:
                return lambda: close(open_analytics(lakes[n].root, for_sql=sql))

            s_lo, s_hi = timed_pair(opened(lo), opened(hi), args.reps)
            print(
                f"setup ({label}), in turn: {lo} runs {s_lo:.3f} s, {hi} runs {s_hi:.3f} s, "
                f"ratio {s_hi / s_lo:.2f} (target ≤ 2)"
            )

        # The cold verification cache: a machine that never read these files hashes each
        # content-addressed file once (every row above ran with the cache warm).
        def cold(n: int) -> Callable[[], object]:
            def opened() -> object:
                shutil.rmtree(cache, ignore_errors=True)
                close(open_analytics(lakes[n].root))
                return None

            return opened

        c_lo, c_hi = timed_pair(cold(lo), cold(hi), args.reps)
        size = {n: sum(f.size for f in lakes[n].data_files()) / 1e6 for n in (lo, hi)}
        print(
            f"setup (every view), verification cache emptied before each (every data file "
            f"hashed): {lo} runs {c_lo:.3f} s ({size[lo]:.1f} MB), {hi} runs {c_hi:.3f} s "
            f"({size[hi]:.1f} MB), ratio {c_hi / c_lo:.2f}"
        )

        big = work / f"fleet-{hi}"

        def ours(for_sql: str | None = QUERY) -> object:
            con = open_analytics(big, for_sql=for_sql)
            try:
                return run_query(con, QUERY)[1]
            finally:
                close(con)

        def every_view() -> object:
            return ours(None)

        def plain() -> object:
            from deltalake import DeltaTable

            files = DeltaTable(str(big / "events")).file_uris(
                file_pruning_predicate=[("type", "=", "detection")]
            )
            con = duckdb.connect()
            try:
                return con.execute(PLAIN, {"files": files}).fetchall()
            finally:
                con.close()

        assert same(ours(), plain()) and same(every_view(), plain()), "the answers differ"
        t_ours, t_plain = timed_pair(ours, plain, args.reps)
        t_every, t_plain2 = timed_pair(every_view, plain, args.reps)
        print(f"query over {hi} runs ({QUERY!r}):")
        print(
            f"  objsearch query (open_analytics(for_sql=…) + run_query) {t_ours:.3f} s, plain "
            f"DuckDB on the table's files {t_plain:.3f} s, ratio {t_ours / t_plain:.2f} (target ≤ 2)"
        )
        print(
            f"  every view made (open_analytics + run_query) {t_every:.3f} s, plain DuckDB "
            f"{t_plain2:.3f} s, ratio {t_every / t_plain2:.2f}"
        )

        logs = write_logs(
            work / "add-logs", [f"add{i:03d}" for i in range(2 * args.reps + 2)], args.add_events
        )
        queue = list(logs.values())

        def add(lake: TableLake) -> Callable[[], object]:
            def one() -> object:
                log = queue.pop()
                refuse_a_log_a_session_holds(log, lake.root)  # what `objsearch lake add` asks first
                return add_log(log, lake, robot="extra", run=log.name)

            return one

        add(lakes[lo])()  # warm both (the first commit of a process loads more)
        add(lakes[hi])()
        a_lo, a_hi = timed_pair(add(lakes[lo]), add(lakes[hi]), args.reps)
        print(
            f"lake add of one run ({args.add_events} events): {lo} runs {a_lo:.3f} s, {hi} runs "
            f"{a_hi:.3f} s, ratio {a_hi / a_lo:.2f} (target: flat)"
        )
        already_there(work, lakes[lo], lakes[hi], args.reps)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
