"""What ``objsearch query``'s process costs after its answer: the command with the query's process
leaving by ``os._exit`` once its ``main`` returns (as it does) against leaving by ``sys.exit``
(the interpreter's teardown, which the command waits for), interleaved in one run.

    python benchmarks/query_exit.py [--rounds 20]

The lake is the lake-log battery's (devtools.lake_battery.build_lake: three runs made by the CLI),
built in a temporary folder; the query is the batteries' (every row of every view, hashed), run
in this process as the batteries run it (devtools.lake_battery.run_cli). Both arms start the
query's process as ``python -P -c`` running the module's ``main`` and then one way of leaving, so
they differ in nothing else. Prints each arm's median wall time, the ratio and the median of the
paired differences.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # devtools/: the checkout's

from devtools.lake_battery import build_lake, every_row_sql, run_cli

MAIN = "import os, sys; from objsearch.replay import query_process as q; code = q.main(); "
ARMS = {
    "sys.exit (teardown)": MAIN + "sys.exit(code)",
    "os._exit (as shipped)": MAIN + "sys.stdout.flush(); sys.stderr.flush(); os._exit(code)",
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=20)
    args = parser.parse_args()

    popen = subprocess.Popen
    arm = {"code": ""}

    def start(argv: list[str], *rest: Any, **kwargs: Any) -> Any:
        if argv[-2:] == ["-m", "objsearch.replay.query_process"]:
            argv = [*argv[:-2], "-c", arm["code"]]
        return popen(argv, *rest, **kwargs)

    # the query's process is started through subprocess.Popen (replay/query_process.py)
    setattr(subprocess, "Popen", start)  # noqa: B010
    with tempfile.TemporaryDirectory() as tmp:
        lake = build_lake(Path(tmp))
        argv = ["query", "--lake", str(lake), "--format", "json", every_row_sql()]
        times: dict[str, list[float]] = {name: [] for name in ARMS}
        for r in range(args.rounds + 1):
            names = list(ARMS) if r % 2 else list(reversed(ARMS))
            for name in names:
                arm["code"] = ARMS[name]
                began = time.perf_counter()
                outcome = run_cli(argv, fork_queries=False)
                if outcome.code != 0:
                    raise SystemExit(f"the query failed: {outcome.stderr}")
                if r:  # the first round warms the caches
                    times[name].append(time.perf_counter() - began)
    teardown, shipped = (times[name] for name in ARMS)
    for name, values in times.items():
        spread = f"[{min(values):.3f}, {max(values):.3f}]"
        print(f"{name:24s} median {statistics.median(values):.3f} s {spread}, n={len(values)}")
    ratio = statistics.median(teardown) / statistics.median(shipped)
    paired = statistics.median(a - b for a, b in zip(teardown, shipped, strict=True))
    print(f"teardown / shipped: {ratio:.2f}x; paired difference median {paired:.3f} s")


if __name__ == "__main__":
    main()
