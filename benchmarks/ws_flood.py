"""The live view's WebSocket battery at benchmark size: hostile clients against a live view
drawing a real log (``objsearch.runtime.wsflood``).

    python benchmarks/ws_flood.py [--cases 2000] [--seed 0] [--max-clients 8]

Opens ``--cases`` hostile connections in rounds of 24 — dripped and silent handshakes, junk,
oversized and wrong handshakes, clients that hold their place, subscribe and never read, hang up
half way or reset mid-stream — while a probe viewer follows the event channel and an agent thread
draws the log over and over. Prints tried / clear error / unchanged / traceback / silent change /
loss, per kind, what the front door counted (evicted, timed out, refused at the cap, dropped as
too slow), the most connections it held and the most bytes that waited for one client, and the
time per case. Exit status 1 unless the last three columns are 0.
"""

from __future__ import annotations

import argparse
import logging
import sys
import tempfile
import time
from pathlib import Path

from objsearch.events import read_log
from objsearch.runtime.standin import in_process_search
from objsearch.runtime.wsflood import report, run_battery
from objsearch.runtime.wsfront import FrontLimits


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--cases", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-clients", type=int, default=8)
    args = ap.parse_args()
    if args.cases < 1 or not 2 <= args.max_clients <= 1024:
        ap.error("--cases must be >= 1 and --max-clients 2-1024")
    # foxglove-sdk logs an error for every client that leaves without a close frame, which
    # the battery's clients do on purpose; the front door's own warnings stay on.
    logging.getLogger("foxglove").setLevel(logging.CRITICAL)
    with tempfile.TemporaryDirectory() as tmp:
        in_process_search(Path(tmp) / "log", 1, "Apple", "kitchen-1")
        events = list(read_log(Path(tmp) / "log"))
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
    return 0 if bad == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
