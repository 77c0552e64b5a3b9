"""The live view's WebSocket battery at benchmark size: hostile clients against a live view
drawing a real log (``devtools.wsflood``).

    python benchmarks/ws_flood.py [--cases 2000] [--seed 0] [--max-clients 8] [--agent-drip 300]

Opens ``--cases`` hostile connections in rounds of 24 — dripped and silent handshakes, junk,
oversized and wrong handshakes, clients that hold their place, subscribe and never read, hang up
half way or reset mid-stream — while a probe viewer follows the event channel and an agent thread
draws the log over and over. Prints tried / clear error / unchanged / traceback / silent change /
loss, per kind, what the front door counted (evicted, timed out, refused at the cap, dropped as
too slow), the most connections it held and the most bytes that waited for one client, and the
time per case. Exit status 1 unless the last three columns are 0.

Then (``--agent-drip N``, 300 by default, 0 to skip) the same front door in the agent as a
process: ``objsearch agent run --live 0`` (default limits) gets N connections dripping a valid
handshake a byte every 0.1 s; prints the agent's threads and open files before and during, whether
a well-behaved viewer gets in meanwhile, and how many drippers the agent closed.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import re
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# devtools/ (the harnesses, not installed) is a folder of the checkout, beside this one's.
sys.path.insert(1, str(Path(__file__).resolve().parents[1]))

from devtools.wsflood import (
    DEADLINE_S,
    Viewer,
    closed_by_server,
    handshake,
    report,
    run_battery,
)
from objsearch.agent.catalogue import STORE
from objsearch.events import read_log
from objsearch.runtime.standin import in_process_search
from objsearch.runtime.wsfront import DEFAULT_HANDSHAKE_TIMEOUT_S, FrontLimits


def agent_drip(n: int) -> bool:
    """``n`` dripping connections against ``objsearch agent run --live 0``; True if bounded."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        zenoh = int(s.getsockname()[1])  # nobody listens: the agent waits for requests
    with tempfile.TemporaryDirectory() as tmp:
        agent = subprocess.Popen(
            [sys.executable, "-m", "objsearch.cli", "agent", "run", "--transport", "zenoh",
             "--connect", f"tcp/127.0.0.1:{zenoh}", "--log", f"{tmp}/log", "--live", "0"],
            stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        try:
            return _drip_at(agent, n)
        finally:
            agent.terminate()
            agent.wait(DEADLINE_S)


def _drip_at(agent: subprocess.Popen[str], n: int) -> bool:
    assert agent.stderr is not None
    port = None
    while port is None:  # the agent says where it serves once it does
        line = agent.stderr.readline()
        if not line:
            raise SystemExit(f"the agent ended before serving the live view ({agent.wait()})")
        if found := re.search(r"live view on ws://127\.0\.0\.1:(\d+)", line):
            port = int(found.group(1))

    def threads() -> int:
        return len(os.listdir(f"/proc/{agent.pid}/task"))

    def files() -> int:
        return len(os.listdir(f"/proc/{agent.pid}/fd"))

    # The agent is still starting threads (zenoh, foxglove) when it prints the address: the
    # baseline is taken once its thread count has held for 2 s.
    seen: list[int] = []
    deadline = time.monotonic() + DEADLINE_S
    while len(seen) < 4 or len(set(seen[-4:])) > 1:
        if time.monotonic() > deadline:
            break
        seen.append(threads())
        time.sleep(0.5)
    before = (threads(), files())
    opening = handshake()
    drippers = []
    for _ in range(n):
        sock = socket.create_connection(("127.0.0.1", port), timeout=DEADLINE_S)
        sock.send(opening[:1])
        drippers.append(sock)
    peak = before
    for i in range(1, 40):  # 4 s of dripping, far short of a whole handshake
        for sock in drippers:
            with contextlib.suppress(OSError):
                sock.send(opening[i : i + 1])
        peak = (max(peak[0], threads()), max(peak[1], files()))
        time.sleep(0.1)
    viewer = Viewer(port)
    got_in = viewer.upgraded and bool(viewer.advertised())
    viewer.close()
    deadline = time.monotonic() + DEFAULT_HANDSHAKE_TIMEOUT_S + DEADLINE_S
    closed = 0
    while time.monotonic() < deadline:
        closed = sum(closed_by_server(sock) for sock in drippers)
        if closed == n:
            break
        time.sleep(0.5)
    for sock in drippers:
        sock.close()
    print(
        f"agent process, {n} dripping connections: threads {before[0]} before, at most {peak[0]} "
        f"during; open files {before[1]} before, at most {peak[1]} during; a viewer got in: "
        f"{'yes' if got_in else 'NO'}; drippers closed by the agent: {closed} of {n}"
    )
    return got_in and closed == n and peak[0] == before[0]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--cases", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-clients", type=int, default=8)
    ap.add_argument("--agent-drip", type=int, default=300, help="0 skips the agent process")
    args = ap.parse_args()
    if args.cases < 1 or not 2 <= args.max_clients <= 1024:
        ap.error("--cases must be >= 1 and --max-clients 2-1024")
    # foxglove-sdk logs an error for every client that leaves without a close frame, which
    # the battery's clients do on purpose; the front door's own warnings stay on.
    logging.getLogger("foxglove").setLevel(logging.CRITICAL)
    with tempfile.TemporaryDirectory() as tmp:
        in_process_search(Path(tmp) / "log", 1, "Apple", "kitchen-1")
        events = list(read_log(Path(tmp) / "log", store=STORE))
    limits = FrontLimits(
        max_clients=args.max_clients, client_queue_bytes=64 * 1024, handshake_timeout_s=2.0
    )
    started = time.perf_counter()
    counts = run_battery(events, args.cases, args.seed, limits=limits)
    seconds = time.perf_counter() - started
    print(
        f"WebSocket battery, seed {args.seed}, cap {limits.max_clients}, queue "
        f"{limits.client_queue_bytes} B, handshake {limits.handshake_timeout_s:g} s:"
    )
    print("\n".join(report(counts)))
    server = counts.server
    assert server is not None
    print(
        f"  front door: accepted {server.accepted}, evicted {server.evicted}, timed out "
        f"{server.timed_out}, refused at the cap {server.refused_full}, dropped as too slow "
        f"{server.dropped_slow}; at most {counts.peak_connections} connections held, at most "
        f"{counts.peak_queue_bytes} bytes waiting for one client"
    )
    print(
        f"  probe: {counts.probe_messages} messages; {seconds:.1f} s "
        f"({1000 * seconds / counts.tried:.1f} ms per case)"
    )
    for problem in counts.problems[:20]:
        print(f"  problem: {problem}")
    bad = counts.traceback + counts.silent_change + counts.loss
    bounded = agent_drip(args.agent_drip) if args.agent_drip > 0 else True
    return 0 if bad == 0 and bounded else 1


if __name__ == "__main__":
    sys.exit(main())
