"""Many writers into one fleet lake: concurrent ``lake add`` processes against one sequential
writer, on the local folder and on a local S3 server (moto's, started here).

    python benchmarks/lake_writers.py [--writers 8] [--runs 50] [--shared 5] [--events 200]
                                      [--where local,s3] [--compact-every N]
                                      [--sequential-on same|local]

Each of ``--writers`` processes commits ``--runs`` runs of its own (a log each, of about
``--events`` synthetic events: ``benchmarks/events.py: synthetic_run``) with ``add_log``, and
every process also commits the same ``--shared`` runs, in its own order: those race from all
sides (one must win, the others find the same content there: a no-op). The baseline is one
process committing every distinct log once, in order, into a second lake in the same run: in
the same place (``--sequential-on same``), or on a local folder (``--sequential-on local``: on
moto's server one process adding 405 runs takes longer than the writers, as moto lists a prefix
by walking every key of the bucket; the lakes are compared as tables, so where the baseline
lives does not matter to the comparison).
Checked, for each place: 0 runs lost, 0 duplicated (every ``(robot, run)`` once, every event id
once), and the concurrent lake equal to the sequential one (the same runs, digests and rows per
run, also after compacting it). Printed: both wall times and their ratio (the concurrent writers
share the machine's cores, so the ratio says what contention costs, not a speed-up), and the
time to read the concurrent lake's runs and counts as written (one file a type a commit) and
after ``compact``. A run lost or doubled is named (with the commit token ``add_log``
acknowledged) and the lake is copied out (from the bucket, before its server stops) into the work
folder, which is then kept for a look. The bucket keeps every version of an object, so a commit
file (``_delta_log/<version>.json``) stored twice — two writers each told they had created it,
the later replacing the earlier (plain moto's conditional put, issue 26) — is counted too.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path

# devtools/ (the harnesses, not installed) is a folder of the checkout, beside this one's.
sys.path.insert(1, str(Path(__file__).resolve().parents[1]))

from devtools.s3server import s3_server
from events import synthetic_run
from objsearch.agent.catalogue import STORE
from objsearch.events import EventLog
from objsearch.events.lake import TableLake, add_log
from objsearch.events.sql_limits import close
from objsearch.replay.analytics import open_analytics, run_query

WRITER = """
import json, sys, time
from pathlib import Path
import objsearch.events.lake.rewrite as lt
from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake, add_log
if int(sys.argv[2]):  # --compact-every: every writer compacts that often, none waits for another
    lt.COMPACT_AT_FILES = int(sys.argv[2])
    lt.COMPACTION_CLAIM_FRESH_S = 0.0
lake = TableLake(sys.argv[1], store=STORE)
started = time.perf_counter()
done = 0
for item in sys.argv[3:]:
    robot, log = item.split("=", 1)
    info = add_log(Path(log), lake, robot=robot, run=Path(log).name)
    done += 1
    # what add_log acknowledged: the run and the commit token its files and rows carry
    print(json.dumps({"acked": [info.robot, info.run, info.commit]}), flush=True)
print(json.dumps({"commits": done, "seconds": time.perf_counter() - started}))
"""


def write_logs(root: Path, names: list[str], events: int) -> dict[str, Path]:
    """A closed log per name, of about ``events`` events, each its own run (own ids)."""
    logs = {}
    for i, name in enumerate(names):
        directory = root / name
        with EventLog.open(directory, name, store=STORE) as log, log.batch():
            for event in synthetic_run(events, seed=i, stream=name):
                log.append(event.type, event.payload, time_ns=event.time_ns, task_id=event.task_id)
        logs[name] = directory
    return logs


def content(lake_root: str) -> tuple[list[tuple[str, str, str, int]], list[tuple[object, ...]]]:
    """The lake's runs (robot, run, digest, events) and per-run counts from a query (rows,
    distinct event ids)."""
    runs = [(r.robot, r.run, r.digest, r.events) for r in TableLake(lake_root, store=STORE).runs()]
    con = open_analytics(lake_root)
    try:
        rows = run_query(
            con,
            "SELECT robot, run, count(*), count(DISTINCT event_id) FROM events "
            "GROUP BY ALL ORDER BY ALL",
        )[1]
    finally:
        close(con)
    return runs, rows


@contextmanager
def place(where: str, work: Path, sequential_on: str = "same") -> Iterator[tuple[str, str]]:
    """Two lake roots (concurrent, sequential) on the local folder or on a fresh S3 server; the
    sequential one on a local folder whatever ``where`` is with ``sequential_on="local"``."""
    if where == "local":
        yield str(work / "lake-concurrent"), str(work / "lake-sequential")
        return
    import boto3

    with s3_server() as settings:
        saved = {k: os.environ.get(k) for k in settings}
        os.environ.update(settings)
        try:
            client = boto3.client("s3")
            client.create_bucket(Bucket="fleet")
            # every version kept: a commit file stored twice shows (commits_stored_twice)
            client.put_bucket_versioning(
                Bucket="fleet", VersioningConfiguration={"Status": "Enabled"}
            )
            sequential = (
                str(work / f"lake-sequential-{where}")
                if sequential_on == "local"
                else "s3://fleet/sequential"
            )
            yield "s3://fleet/concurrent", sequential
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v


def run_place(
    where: str,
    work: Path,
    own: Mapping[int, list[Path]],
    shared: list[Path],
    compact_every: int = 0,
    sequential_on: str = "same",
) -> tuple[bool, str]:
    with place(where, work, sequential_on) as (concurrent_root, sequential_root):
        TableLake(concurrent_root, store=STORE).create()
        started = time.perf_counter()
        procs = []
        for w, logs in own.items():
            # the shared runs, in an order of this writer's own, among its own runs
            turn = shared[w % len(shared) :] + shared[: w % len(shared)] if shared else []
            items = [f"r{w:02d}={p}" for p in logs]
            for k, p in enumerate(turn):
                items.insert((k * len(items)) // max(1, len(turn)), f"shared={p}")
            procs.append(
                subprocess.Popen(
                    [sys.executable, "-c", WRITER, concurrent_root, str(compact_every), *items],
                    stdout=subprocess.PIPE,
                    text=True,
                    env={**os.environ},
                )
            )
        outs = [p.communicate(timeout=3600) for p in procs]
        concurrent_s = time.perf_counter() - started
        failed = [i for i, p in enumerate(procs) if p.returncode != 0]
        docs = [
            json.loads(ln) for o, _ in outs for ln in (o or "").splitlines() if ln.startswith("{")
        ]
        commits = sum(d["commits"] for d in docs if "commits" in d)
        acked = {(d["acked"][0], d["acked"][1]): d["acked"][2] for d in docs if "acked" in d}

        sequential = TableLake(sequential_root, store=STORE)
        started = time.perf_counter()
        for w, logs in own.items():
            for p in logs:
                add_log(p, sequential, robot=f"r{w:02d}", run=p.name)
        for p in shared:
            add_log(p, sequential, robot="shared", run=p.name)
        sequential_s = time.perf_counter() - started

        twice = commits_stored_twice(concurrent_root)
        files = len(TableLake(concurrent_root, store=STORE).data_files())
        started = time.perf_counter()
        got_runs, got_rows = content(concurrent_root)
        uncompacted_s = time.perf_counter() - started
        there = [(r[0], r[1]) for r in got_runs]
        if set(acked) - set(there) or len(there) != len(set(there)):
            keep_for_a_look(concurrent_root, work / f"kept-{where}", acked, there)
        want_runs, want_rows = content(sequential_root)
        started = time.perf_counter()
        TableLake(concurrent_root, store=STORE).compact(vacuum_hours=None)
        compact_s = time.perf_counter() - started
        started = time.perf_counter()
        compacted = content(concurrent_root)
        compacted_s = time.perf_counter() - started
    expected = {(f"r{w:02d}", p.name) for w, logs in own.items() for p in logs}
    expected |= {("shared", p.name) for p in shared}
    present = [(r[0], r[1]) for r in got_runs]
    lost = len(expected - set(present))
    duplicated = len(present) - len(set(present))
    duplicated += sum(1 for r in got_rows if r[2] != r[3])  # an event id twice in one run
    ids = sum(int(str(r[3])) for r in got_rows)
    equal = got_runs == want_runs and got_rows == want_rows and compacted == (got_runs, got_rows)
    ok = not failed and lost == 0 and duplicated == 0 and equal and not twice
    print(
        f"{where:>6}: {len(own)} writers, {commits} add_log calls -> {len(present)} runs, "
        f"{ids:,} events; lost {lost}, duplicated {duplicated}, equal to sequential: {equal}"
        + (f"; every writer compacting past {compact_every} files" if compact_every else "")
        + (f", writers failed: {failed}" if failed else "")
        + (
            f"; commit files stored more than once: {len(twice)}"
            + (f" ({', '.join(twice[:5])})" if twice else "")
            if "://" in concurrent_root
            else ""
        )
    )
    print(
        f"{'':>6}  concurrent {concurrent_s:.1f} s, sequential (one process, "
        f"{len(expected)} adds, into {_where(sequential_root)}) {sequential_s:.1f} s, "
        f"ratio {concurrent_s / sequential_s:.2f}"
    )
    print(
        f"{'':>6}  runs and a count of every run's events and ids (open_analytics + query): "
        f"{uncompacted_s:.1f} s over the concurrent lake as written ({files} data files); "
        f"lake compact {compact_s:.1f} s; then {compacted_s:.1f} s"
    )
    return ok, where


def commits_stored_twice(root: str) -> list[str]:
    """The commit files of a lake on the (versioned) bucket that were stored more than once:
    of two writers of one version only one may create its file (``If-None-Match: *``)."""
    if "://" not in root:
        return []
    import boto3

    bucket, _, prefix = root.removeprefix("s3://").partition("/")
    stored: dict[str, int] = {}
    pages = boto3.client("s3").get_paginator("list_object_versions")
    for page in pages.paginate(Bucket=bucket, Prefix=f"{prefix}/events/_delta_log/"):
        for version in page.get("Versions", []):
            name = version["Key"].rsplit("/", 1)[-1]
            if name.endswith(".json") and name.removesuffix(".json").isdigit():
                stored[name] = stored.get(name, 0) + 1
    return sorted(k for k, n in stored.items() if n > 1)


def keep_for_a_look(
    root: str, into: Path, acked: Mapping[tuple[str, str], str], there: list[tuple[str, str]]
) -> None:
    """A lake that lost or doubled runs: name them (with the commit token add_log acknowledged:
    its data files are ``part-<token>.zstd.parquet``, its commit names them) and copy the lake
    (its Delta log, every file) out of the bucket before the server stops."""
    import pyarrow.fs as pafs

    for key in sorted(set(acked) - set(there)):
        print(f"  LOST after add_log returned: {key[0]}/{key[1]}, commit token {acked[key]}")
    for key in sorted({k for k in there if there.count(k) > 1}):
        print(f"  TWICE: {key[0]}/{key[1]}")
    if "://" in root:
        fs = pafs.S3FileSystem(
            endpoint_override=os.environ["AWS_ENDPOINT_URL"],
            scheme="http" if os.environ["AWS_ENDPOINT_URL"].startswith("http://") else "https",
            access_key=os.environ["AWS_ACCESS_KEY_ID"],
            secret_key=os.environ["AWS_SECRET_ACCESS_KEY"],
            region=os.environ.get("AWS_REGION", "us-east-1"),
        )
        pafs.copy_files(root.removeprefix("s3://"), str(into), source_filesystem=fs)
    else:
        shutil.copytree(root, into)
    print(f"  the lake is kept in {into}")


def _where(root: str) -> str:
    return "the bucket" if "://" in root else "a local folder"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--writers", type=int, default=8)
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--shared", type=int, default=5)
    ap.add_argument("--events", type=int, default=200)
    ap.add_argument("--where", default="local,s3")
    ap.add_argument(
        "--compact-every",
        type=int,
        default=0,
        help="each writer's lake add compacts once the table holds more files than this, "
        "whatever another writer claimed (0: the default, COMPACT_AT_FILES)",
    )
    ap.add_argument(
        "--sequential-on",
        choices=["same", "local"],
        default="same",
        help="where the sequential baseline lake is: the same place as the concurrent one "
        "(default) or a local folder (compared as tables)",
    )
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="objsearch-bench-lake-writers-"))
    places = [w for w in args.where.split(",") if w]
    results: list[tuple[bool, str]] = []
    print(
        "concurrent lake writers; command: python benchmarks/lake_writers.py "
        + " ".join(sys.argv[1:])
    )
    try:
        names = {w: [f"w{w:02d}-run{i:03d}" for i in range(args.runs)] for w in range(args.writers)}
        every = [n for ns in names.values() for n in ns]
        shared_names = [f"shared-run{i:03d}" for i in range(args.shared)]
        logs = write_logs(work / "logs", every + shared_names, args.events)
        own = {w: [logs[n] for n in ns] for w, ns in names.items()}
        shared = [logs[n] for n in shared_names]
        results = [
            run_place(w, work, own, shared, args.compact_every, args.sequential_on) for w in places
        ]
    finally:
        if all(ok for ok, _ in results) and len(results) == len(places):
            shutil.rmtree(work, ignore_errors=True)
        else:
            print(f"kept {work} (its logs and any kept lake) for a look")
    bad = [where for ok, where in results if not ok]
    print("all places: 0 lost, 0 duplicated, equal to sequential" if not bad else f"FAILED: {bad}")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
