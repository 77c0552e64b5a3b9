"""Bag ingest against plain AnyReader iteration with deserialisation, over the same bags.

    python benchmarks/ingest.py [--reps 3] [--format ros2-mcap] [--bags 2]

Records one simulated run (scene 1, targets Apple and Cup, all 8 starts: 16 searches, odometry
at 10 Hz) per bag with ``objsearch record`` (bags differ by their start time), then per rep:

* raw: ``AnyReader`` over every message of one bag, ``deserialize`` each (the floor any reader
  of the bag pays);
* ingest: ``objsearch ingest`` of the same bag into a fresh lake, 1 worker (hash, read,
  deserialise what it converts, convert, validate the agent's events, write Parquet, commit);
* ingest of ``--bags`` bags with 1 worker and with 2 workers (scaling), and with
  ``--engine ray`` on a local 2-CPU Ray instance when Ray is installed (started once, outside
  the timing);
* what the driver-commits design costs: pickling a bag's tables and report (what travels from
  a worker to the driver) and committing them.

Prints medians, messages/s and MB/s, and the ratios (target: ingest ≥ 0.8 × raw).
"""

from __future__ import annotations

import argparse
import pickle
import shutil
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from objsearch.pipeline.bags.engines import Engine, RayEngine
from objsearch.pipeline.bags.formats import BagFormat, storage_files
from objsearch.pipeline.bags.ingest import BagTask, commit_converted, convert_bag, ingest
from objsearch.pipeline.bags.lake import FleetBagLake
from objsearch.pipeline.bags.readers import iter_raw
from objsearch.pipeline.bags.record import DEFAULT_START_NS, record
from objsearch.ros.topics import TopicMap


def record_bags(work: Path, fmt: BagFormat, n: int, *, own_seeds: bool = False) -> list[Path]:
    """``n`` bags of one simulated run each (scene 1, Apple and Cup, all 8 starts), on clocks
    10 days apart; with ``own_seeds`` each is a recording of its own (seed ``i``), else all
    are one recording on ``n`` clocks (which ingest keeps once)."""
    bags = []
    for i in range(n):
        name = f"run{i}.bag" if fmt is BagFormat.ROS1 else f"run{i}"
        rec = record(
            work / name,
            fmt,
            scenes=[1],
            targets=["Apple", "Cup"],
            start_ns=DEFAULT_START_NS + i * 86_400 * 10**9,
            seed=i if own_seeds else 0,
        )
        bags.append(rec.path)
    return bags


def size_of(bag: Path) -> int:
    return sum(f.stat().st_size for f in storage_files(bag))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--format", default="ros2-mcap", choices=[f.value for f in BagFormat])
    ap.add_argument("--bags", type=int, default=2, help="bags for the 1 → 2 worker scaling")
    args = ap.parse_args()
    fmt = BagFormat(args.format)
    work = Path(tempfile.mkdtemp(prefix="objsearch-bench-ingest-"))
    try:
        bags = record_bags(work, fmt, args.bags)
        bag = bags[0]
        messages = sum(1 for _ in iter_raw(bag))
        mb = size_of(bag) / 1e6
        print(f"bag: {fmt.value}, {messages} messages, {mb:.1f} MB; {args.reps} reps, medians")
        ray_engine: Engine | None = None
        try:
            import ray

            ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
            ray_engine = RayEngine()
        except ImportError:
            print("(Ray is not installed: no --engine ray figures)")
        raw_t: list[float] = []
        ing_t: list[float] = []
        one_t: list[float] = []
        two_t: list[float] = []
        ray_t: list[float] = []
        ship_t: list[float] = []
        commit_t: list[float] = []
        for rep in range(args.reps):
            t0 = time.perf_counter()
            n = sum(1 for _ in iter_raw(bag))
            raw_t.append(time.perf_counter() - t0)
            assert n == messages
            lake = work / f"lake-{rep}"
            t0 = time.perf_counter()
            [res] = ingest([bag], lake)
            ing_t.append(time.perf_counter() - t0)
            assert res.error is None and res.committed > 0, res
            fleets: list[tuple[str, dict[str, Any], list[float]]] = [
                ("w1", {"workers": 1}, one_t),
                ("w2", {"workers": 2}, two_t),
            ]
            if ray_engine is not None:
                fleets.append(("ray", {"engine": ray_engine}, ray_t))
            for label, how, times in fleets:
                lake = work / f"lake-{rep}-{label}"
                t0 = time.perf_counter()
                results = ingest(bags, lake, **how)
                times.append(time.perf_counter() - t0)
                assert all(r.error is None for r in results)
                shutil.rmtree(lake)
            converted = convert_bag(BagTask(bag, TopicMap()))
            t0 = time.perf_counter()
            shipped = pickle.dumps(converted, protocol=5)
            pickle.loads(shipped)
            ship_t.append(time.perf_counter() - t0)
            lake = work / f"lake-{rep}-commit"
            t0 = time.perf_counter()
            assert commit_converted(FleetBagLake(lake), converted, "robot").committed > 0
            commit_t.append(time.perf_counter() - t0)
            shutil.rmtree(lake)
        raw, ing = statistics.median(raw_t), statistics.median(ing_t)
        print(f"{'':24}{'median s':>10}{'msg/s':>10}{'MB/s':>8}")
        print(f"{'raw AnyReader+deser':24}{raw:10.2f}{messages / raw:10.0f}{mb / raw:8.2f}")
        print(f"{'ingest (1 bag)':24}{ing:10.2f}{messages / ing:10.0f}{mb / ing:8.2f}")
        print(f"ingest / raw throughput: {raw / ing:.2f} (target ≥ 0.8)")
        one, two = statistics.median(one_t), statistics.median(two_t)
        total = messages * len(bags)
        print(f"{len(bags)} bags, 1 worker: {one:.2f} s ({total / one:.0f} msg/s)")
        print(f"{len(bags)} bags, 2 workers: {two:.2f} s ({total / two:.0f} msg/s)")
        print(f"speed-up 1 → 2 workers: {one / two:.2f}×")
        if ray_t:
            ray_s = statistics.median(ray_t)
            print(
                f"{len(bags)} bags, --engine ray (local, 2 CPUs): {ray_s:.2f} s ({total / ray_s:.0f} msg/s)"
            )
        ship, commit = statistics.median(ship_t), statistics.median(commit_t)
        print(
            f"worker → driver: {len(shipped) / 1e6:.1f} MB pickled, {ship:.3f} s to pickle and "
            f"unpickle; driver commit {commit:.3f} s ({(ship + commit) / ing:.0%} of ingest)"
        )
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
