"""The request fuzzer at scale against real processes on 127.0.0.1 (router, ``objsearch robot
sim``, ``objsearch agent run`` over Zenoh).

    python benchmarks/request_fuzz.py [--cases 3000] [--seed 12]

Sends ``--cases`` broken requests (find, open, reset, goal; see ``devtools.requestfuzz``),
then a valid search whose result must equal the in-process simulator's, and prints the counts:
tried / error-answered (each error names the broken field) / dropped (each with its log line in
the receiving process) / served / crashed (a process that died or printed a traceback) / wrong
(anything else), with the time per case.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

# devtools/ (the harnesses, not installed) is a folder of the checkout, beside this one's.
sys.path.insert(1, str(Path(__file__).resolve().parents[1]))

from devtools.requestfuzz import Rig, free_port, fuzz_rig, simulated


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--cases", type=int, default=3000)
    ap.add_argument("--seed", type=int, default=12)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        expected = simulated(work / "inproc")
        rig = Rig(work, free_port())
        rig.start()
        started = time.perf_counter()
        try:
            counts, _ = fuzz_rig(rig, args.cases, args.seed, expected)
        finally:
            seconds = time.perf_counter() - started
            rig.stop()
        print(f"request fuzz, seed {args.seed}: {counts.line()}")
        print(
            f"  drops logged by the agent {counts.drops_by['agent']}, by the robot "
            f"{counts.drops_by['robot']}; {seconds:.1f} s ({1000 * seconds / counts.tried:.1f} ms "
            "per case, including the final search)"
        )
        for problem in counts.wrong[:20]:
            print(f"  wrong: {problem}")
    return 0 if not counts.wrong and not counts.crashed else 1


if __name__ == "__main__":
    sys.exit(main())
