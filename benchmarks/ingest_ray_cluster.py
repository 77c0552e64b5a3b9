"""Ray ingest on a multi-node Ray cluster started on this machine, against one process.

    python benchmarks/ingest_ray_cluster.py [--bags 8] [--nodes 2] [--reps 3] [--format ros2-mcap]

Starts a Ray cluster of ``--nodes`` nodes of one CPU each with Ray's own command line — ``ray
start --head --node-ip-address=127.0.0.1 --block``, then ``ray start
--address=127.0.0.1:PORT --block`` per further node, each node with its own ``--temp-dir``
and its own free ports (two raylets on one machine must not share either) — and stops it at
the end by ending the ``ray start`` processes it started and any process still running from
its temp folders (never ``ray stop``: that stops every Ray on the machine). Ray 2.60 wants
``RAY_AUTH_MODE=disabled`` for a cluster without token authentication; it is set for the
cluster's processes and this one.

Records ``--bags`` bags (one simulated run each, as ``benchmarks/ingest.py`` records them but
each with its own seed: bags that differ only by their start time are one recording, which
ingest keeps once, in a run whose clock depends on which bag came first), then per rep ingests all of them into a fresh lake:

* one process: ``ingest(bags, lake)`` (the inline engine, the baseline);
* Ray: ``ingest(bags, lake, engine=RayEngine(address=…))`` from a driver joined to the cluster
  once (``ray.init(address=…)``) and warmed by one untimed ingest — the start-up (the driver's
  connection, each node's worker processes importing objsearch) paid once, as a long-running
  ingest service would;
* and once, the CLI joining the cluster: ``objsearch ingest --engine ray --address
  127.0.0.1:PORT`` (start-up included).

Checks both lakes hold the same runs (digests) and that the Ray tasks ran on every node. Prints
medians, the ratio one process / Ray (target ≥ 1.6 with 2 nodes of one CPU) and the machine's
load average before and after (a 2-core machine shared with other jobs: a ratio measured under
load is a ratio under that load).
"""

from __future__ import annotations

import argparse
import functools
import importlib
import os
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

from ingest import record_bags

from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake
from objsearch.pipeline.bags.engines import RayEngine
from objsearch.pipeline.bags.formats import BagFormat
from objsearch.pipeline.bags.ingest import ingest

RAY = str(Path(sys.executable).with_name("ray"))
#: Ray 2.60 starts a cluster with token authentication unless told otherwise.
RAY_ENV = {"RAY_AUTH_MODE": "disabled", "RAY_USAGE_STATS_ENABLED": "0"}


def free_ports(n: int) -> list[int]:
    """``n`` distinct loopback ports free now."""
    socks = []
    try:
        for _ in range(n):
            s = socket.socket()
            s.bind(("127.0.0.1", 0))
            socks.append(s)
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def node_args(temp: Path, head: bool) -> list[str]:
    """The flags one node needs to live beside others on one machine: its own temp folder and
    ports (Ray's defaults are fixed ports, which a second raylet would take again)."""
    ports = free_ports(7)
    base = ports[6] % 20000 + 20000  # a range of 40 worker ports
    args = [
        "--node-ip-address=127.0.0.1",
        "--num-cpus=1",
        "--object-store-memory=300000000",
        f"--temp-dir={temp}",
        f"--node-manager-port={ports[0]}",
        f"--object-manager-port={ports[1]}",
        f"--metrics-export-port={ports[2]}",
        f"--dashboard-agent-listen-port={ports[3]}",
        f"--dashboard-agent-grpc-port={ports[4]}",
        f"--runtime-env-agent-port={ports[5]}",
        f"--min-worker-port={base}",
        f"--max-worker-port={base + 40}",
        "--disable-usage-stats",
        "--block",
    ]
    if head:
        args += ["--include-dashboard=false"]
    return args


@contextmanager
def cluster(nodes: int, work: Path) -> Iterator[str]:
    """A Ray cluster of ``nodes`` one-CPU nodes on this machine; its GCS address."""
    import ray

    env = {**os.environ, **RAY_ENV}
    [port] = free_ports(1)
    address = f"127.0.0.1:{port}"
    temps = [Path(tempfile.mkdtemp(prefix=f"r{i}-", dir="/tmp")) for i in range(nodes)]
    procs: list[subprocess.Popen[bytes]] = []
    try:
        procs.append(
            subprocess.Popen(
                [RAY, "start", "--head", f"--port={port}", *node_args(temps[0], head=True)],
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=open(work / "ray-head.log", "wb"),  # noqa: SIM115 (closed with the process)
                start_new_session=True,
            )
        )
        wait_for(functools.partial(has_nodes, address, 1), "the head node")
        for i in range(1, nodes):
            procs.append(
                subprocess.Popen(
                    [RAY, "start", f"--address={address}", *node_args(temps[i], head=False)],
                    env=env,
                    stdout=subprocess.DEVNULL,
                    stderr=open(work / f"ray-node{i}.log", "wb"),  # noqa: SIM115
                    start_new_session=True,
                )
            )
            wait_for(functools.partial(has_nodes, address, i + 1), f"node {i + 1}")
        yield address
    finally:
        with suppress(Exception):
            ray.shutdown()
        for p in procs:  # ray start --block ends the node's processes when it is ended
            with suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGTERM)
        for p in procs:
            with suppress(subprocess.TimeoutExpired):
                p.wait(timeout=30)
        leftovers = our_processes(temps)
        for pid in leftovers:  # a daemon that outlived its ray start: ours by its temp folder
            with suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        for t in temps:
            shutil.rmtree(t, ignore_errors=True)


def our_processes(temps: list[Path]) -> list[int]:
    """Processes whose command line names one of the cluster's temp folders (``/proc``)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if any(str(t) in cmdline for t in temps):
            found.append(int(entry.name))
    return found


def alive_nodes(address: str) -> int:
    """Nodes the cluster's GCS reports alive (a short-lived query process: the driver joins
    only once, later)."""
    code = (
        f"import ray; ray.init(address={address!r}, log_to_driver=False); "
        "print(sum(n['Alive'] for n in ray.nodes()))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        env={**os.environ, **RAY_ENV},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    lines = out.stdout.strip().splitlines()
    return int(lines[-1]) if out.returncode == 0 and lines and lines[-1].isdigit() else 0


def has_nodes(address: str, n: int) -> bool:
    return alive_nodes(address) >= n


def wait_for(check: Callable[[], bool], what: str, timeout_s: float = 300.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if check():
            return
        time.sleep(1.0)
    raise RuntimeError(f"{what} of the Ray cluster did not come up in {timeout_s:.0f} s")


def digests(lake: Path) -> list[tuple[str, str]]:
    return sorted((r.run, r.digest) for r in TableLake(lake, store=STORE).runs())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--bags", type=int, default=8)
    ap.add_argument("--nodes", type=int, default=2)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--format", default="ros2-mcap", choices=[f.value for f in BagFormat])
    args = ap.parse_args()
    os.environ.update(RAY_ENV)
    fmt = BagFormat(args.format)
    work = Path(tempfile.mkdtemp(prefix="objsearch-bench-ray-cluster-"))
    print("command: python benchmarks/ingest_ray_cluster.py " + " ".join(sys.argv[1:]))
    print(f"load average at start: {os.getloadavg()[0]:.1f} ({os.cpu_count()} cores)")
    try:
        # a recording each: the same run on 8 clocks would be one run
        bags = record_bags(work, fmt, args.bags, own_seeds=True)
        print(f"{len(bags)} bags ({fmt.value}) recorded")
        with cluster(args.nodes, work) as address:
            ray: Any = importlib.import_module("ray")

            started = time.perf_counter()
            ray.init(address=address, log_to_driver=False)
            joined_s = time.perf_counter() - started
            nodes = [n for n in ray.nodes() if n["Alive"]]
            print(
                f"cluster: {len(nodes)} nodes alive at {address} "
                f"({', '.join(str(n['NodeManagerPort']) for n in nodes)} node-manager ports), "
                f"{ray.cluster_resources().get('CPU', 0):.0f} CPUs; driver joined in {joined_s:.1f} s"
            )
            engine = RayEngine(address=address)
            started = time.perf_counter()
            ingest(bags, work / "warm", engine=engine)  # each node's workers start, import
            print(
                f"warm-up ingest through Ray (start-up paid here): {time.perf_counter() - started:.1f} s"
            )
            one_t: list[float] = []
            ray_t: list[float] = []
            for rep in range(args.reps):
                for name, kwargs, times in (
                    ("one", {}, one_t),
                    ("ray", {"engine": engine}, ray_t),
                ):
                    lake = work / f"{name}-{rep}"
                    started = time.perf_counter()
                    results = ingest(bags, lake, **kwargs)  # type: ignore[arg-type]
                    times.append(time.perf_counter() - started)
                    assert all(r.error is None for r in results), [r.error for r in results]
            one_s, ray_s = statistics.median(one_t), statistics.median(ray_t)
            print(f"{len(bags)} bags, one process: {one_s:.2f} s ({_times(one_t)})")
            print(
                f"{len(bags)} bags, Ray on {args.nodes} nodes x 1 CPU, start-up paid once: "
                f"{ray_s:.2f} s ({_times(ray_t)})"
            )
            print(f"speed-up one process / Ray: {one_s / ray_s:.2f}x (target >= 1.6)", flush=True)
            same = _compare(work / "one-0", work / f"ray-{args.reps - 1}")
            # Where the tasks ran: one task per node at least (each asks for a whole CPU).
            per_node = _task_nodes(ray)
            ray.shutdown()
            started = time.perf_counter()
            cli = subprocess.run(
                [
                    str(Path(sys.executable).with_name("objsearch")),
                    "ingest",
                    *map(str, bags),
                    "--lake",
                    str(work / "cli"),
                    "--engine",
                    "ray",
                    "--address",
                    address,
                    "--no-progress",
                    "--format",
                    "json",
                ],
                capture_output=True,
                text=True,
                timeout=1800,
                check=False,
            )
            cli_s = time.perf_counter() - started
            assert cli.returncode == 0, cli.stderr[-2000:]
            same = _compare(work / "one-0", work / "cli") and same
        print(f"a probe of one-CPU Ray tasks, tasks per node: {per_node}")
        print(f"objsearch ingest --engine ray --address (joins, start-up included): {cli_s:.1f} s")
        print(f"same runs and digests in every lake: {same}")
        print(f"load average at end: {os.getloadavg()[0]:.1f}")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0 if same else 1


def _times(times: list[float]) -> str:
    return f"median of {len(times)}: " + ", ".join(f"{t:.1f}" for t in times)


def _compare(a: Path, b: Path) -> bool:
    """Whether two lakes hold the same runs with the same digests; prints what differs."""
    left, right = digests(a), digests(b)
    if left != right:
        print(f"{a.name} and {b.name} differ: {sorted(set(left) ^ set(right))}")
    return left == right


def _task_nodes(ray: Any) -> dict[str, int]:
    """Node id (8 hex) → tasks it ran, from a short probe of 2 × nodes one-CPU tasks."""
    import collections

    def where() -> str:
        time.sleep(0.5)
        return str(ray.get_runtime_context().get_node_id())[:8]

    task = ray.remote(num_cpus=1)(where)
    nodes = len([n for n in ray.nodes() if n["Alive"]])
    got = ray.get([task.remote() for _ in range(2 * nodes)])
    return dict(collections.Counter(got))


if __name__ == "__main__":
    raise SystemExit(main())
