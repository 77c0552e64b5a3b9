"""What hashing the fleet lake's data files on first sight would cost a query on S3.

    python benchmarks/lake_s3_hash.py [--runs 20] [--events 5000] [--reps 3]

A fleet lake of ``--runs`` runs (each ``lake add`` of a synthetic log of ``--events`` events,
``benchmarks/lake_writers.py``'s, then compacted) on a local S3 server (moto's, started here).
Timed, median of ``--reps``, in turn: what ``objsearch query`` pays to open the lake today
(``open_analytics``: the table's log read, views bound; no request a data file but the footers
the views bind); one ``HEAD`` a data file (``get_file_info``: what a cache keyed by size and
last-modified needs each query); and downloading and hashing every data file (what a first sight
costs a machine, per file that is new to it). On a local server a byte costs far less than over
a network: the ratio of the download to the setup is the least it would be against a real
bucket. Decides whether a query on S3 hashes on first sight (``docs/analytics.md``).
"""

from __future__ import annotations

import argparse
import hashlib
import os
import shutil
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

# devtools/ (the harnesses, not installed) is a folder of the checkout, beside this one's.
sys.path.insert(1, str(Path(__file__).resolve().parents[1]))

import boto3
from lake_writers import write_logs

from devtools.s3server import s3_server
from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake, add_log
from objsearch.events.lake.storage import _filesystem
from objsearch.events.sql_limits import close
from objsearch.replay.analytics import open_analytics


def median_in_turn(fns: list[Callable[[], object]], reps: int) -> list[float]:
    times: list[list[float]] = [[] for _ in fns]
    for _ in range(reps):
        for i, fn in enumerate(fns):
            started = time.perf_counter()
            fn()
            times[i].append(time.perf_counter() - started)
    return [statistics.median(t) for t in times]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--events", type=int, default=5000)
    ap.add_argument("--reps", type=int, default=3)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="objsearch-bench-s3-hash-"))
    os.environ["OBJSEARCH_CACHE"] = str(work / "cache")
    logs = write_logs(work / "logs", [f"run{i:03d}" for i in range(args.runs)], args.events)
    with s3_server() as settings:
        os.environ.update(settings)
        boto3.client("s3").create_bucket(Bucket="fleet")
        lake = TableLake("s3://fleet/lake", store=STORE)
        for name, log in logs.items():
            add_log(log, lake, robot="r", run=name)
        lake.compact(vacuum_hours=0)
        files = lake.data_files()
        fs, base = _filesystem(lake.uri)
        total = sum(f.size for f in files)

        def setup() -> object:
            close(open_analytics(lake.root))
            return None

        def heads() -> object:
            return fs.get_file_info([f"{base}/{f.path}" for f in files])

        def download_and_hash() -> object:
            for f in files:
                with fs.open_input_file(f"{base}/{f.path}") as fh:
                    hashlib.sha256(fh.read()).hexdigest()
            return None

        t_setup, t_heads, t_hash = median_in_turn([setup, heads, download_and_hash], args.reps)
    shutil.rmtree(work, ignore_errors=True)
    print(
        f"fleet lake on moto's S3 server, {args.runs} runs of {args.events} events compacted: "
        f"{len(files)} data files, {total / 1e6:.2f} MB; {args.reps} reps, medians"
    )
    print(f"  command: python benchmarks/lake_s3_hash.py {' '.join(sys.argv[1:])}".rstrip())
    print(f"  query setup (open_analytics)           {t_setup:.3f} s")
    print(f"  HEAD every data file (get_file_info)   {t_heads:.3f} s  ({t_heads / t_setup:.2f}×)")
    print(f"  download and hash every data file      {t_hash:.3f} s  ({t_hash / t_setup:.2f}×)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
