"""A small lake of real simulated runs to try the analytics on (examples/analytics.ipynb, its test).

Each run is one (home, strategy, schedule seed): the bench's own job (experiments/runner.py) with
its event log kept, then added to a fleet lake as robot ``sim``, run ``<home>-<strategy>-s<seed>``.
Seconds, not minutes: a few homes, scenes, targets and one start per search.

    python -m objsearch.experiments.sample_lake out/sample-lake
"""

from __future__ import annotations

import argparse
import tempfile
from collections.abc import Sequence
from pathlib import Path

from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake, add_log, open_lake
from objsearch.experiments.runner import Job, run_job

HOMES = ("ithor-01", "procthor-00")
STRATEGIES = ("wpl", "ecost")
SEEDS = (0, 1)
SCENES = (1, 2, 3)
TARGETS = ("Apple", "Cup", "Phone")


def run_name(home: str, strategy: str, seed: int) -> str:
    return f"{home}-{strategy}-s{seed}"


def write_sample_lake(
    out: Path,
    *,
    homes: Sequence[str] = HOMES,
    strategies: Sequence[str] = STRATEGIES,
    seeds: Sequence[int] = SEEDS,
    scenes: Sequence[int] = SCENES,
    targets: Sequence[str] = TARGETS,
) -> TableLake:
    """Run every (home, strategy, seed) on ``stats-<seed>`` schedules and add each log to a
    fleet lake at ``out`` (new or empty); returns the lake."""
    lake = open_lake(out, store=STORE)
    with tempfile.TemporaryDirectory(prefix="objsearch-sample-") as tmp:
        for home in homes:
            for strategy in strategies:
                for seed in seeds:
                    name = run_name(home, strategy, seed)
                    log = Path(tmp) / name
                    run_job(
                        Job(
                            "sample",
                            home,
                            f"stats-{seed}",
                            strategy,
                            "all",
                            targets=tuple(targets),
                            scenes=tuple(scenes),
                            log_dir=str(log),
                            starts_per_search=1,
                        )
                    )
                    add_log(log, lake, robot="sim", run=name, date="2026-01-01")
    return lake


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path, help="the lake folder to write (new or empty)")
    args = parser.parse_args(argv)
    lake = write_sample_lake(args.out)
    print(f"wrote {len(lake.runs())} runs to {lake.root}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["HOMES", "SEEDS", "STRATEGIES", "run_name", "write_sample_lake"]
