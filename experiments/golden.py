"""Golden logs: small recorded runs whose decisions today's code must still make.

``python -m objsearch.experiments.golden DIR`` (``make bless`` passes ``tests/replay/golden``) re-records
them after an intended change; ``tests/replay/test_golden.py`` replays them and fails with the
decisions that changed. The folder is always the caller's: an installed package has no tests.
Each golden is a simulated run of the paper home with a fixed seed and a fixed wall clock, so
re-blessing unchanged code rewrites the same bytes.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from objsearch.agent.policy import Method
from objsearch.agent.scene_graph import UpdateMode
from objsearch.agent.session import load_context
from objsearch.agent.strategies import RunSpec
from objsearch.sim.longterm import run_schedule

#: A lake holding one ingested bag: the path a real robot's recording takes.
BAG_LAKE = "lake-from-bag"
BAG_ROBOT = "sim"
FIXED_WALL_CLOCK_NS = 1_767_225_600_000_000_000  # 2026-01-01T00:00:00Z


@dataclass(frozen=True, slots=True)
class GoldenRun:
    name: str
    method: Method
    update_mode: UpdateMode
    scenes: tuple[int, ...]
    targets: tuple[str, ...]
    starts: tuple[str, ...]


GOLDEN_RUNS = (
    GoldenRun(
        "sim-wpl-updates",
        Method.WPL,
        UpdateMode.ALL,
        scenes=(1, 2),
        targets=("Apple", "Vase"),
        starts=("kitchen-1", "bedroom-2"),
    ),
    GoldenRun(
        "sim-rvp-targets",
        Method.RVP,
        UpdateMode.TARGETS,
        scenes=(3,),
        targets=("Cup", "Laptop"),
        starts=("living-1", "bathroom-2"),
    ),
)


def record(run: GoldenRun, log_dir: Path, *, home: str = "paper") -> None:
    """Run the golden's searches into ``log_dir`` (which must not exist yet)."""
    ctx = load_context(home)
    spec = RunSpec.of(
        home,
        ctx.home.digest,
        run.method.value,
        update_mode=run.update_mode,
        schedule="table2",
        params={"golden": run.name},
    )
    run_schedule(
        log_dir,
        spec,
        targets=run.targets,
        scenes=run.scenes,
        starts=run.starts,
        wall_clock=lambda: FIXED_WALL_CLOCK_NS,
    )


def record_bag_lake(lake_dir: Path) -> None:
    """Record a short simulated run as an MCAP bag and ingest it into a fresh lake.

    The bag's agent events carry the wall clock of the recording, so unlike the log goldens
    this lake's run name (the bag's digest) changes at every re-bless.
    """
    from objsearch.pipeline.bags.formats import BagFormat
    from objsearch.pipeline.bags.ingest import ingest
    from objsearch.pipeline.bags.record import record as record_bag

    with tempfile.TemporaryDirectory(prefix="objsearch-golden-") as tmp:
        bag = Path(tmp) / "golden-bag"
        record_bag(
            bag,
            BagFormat.ROS2_MCAP,
            scenes=(4,),
            targets=("Bowl", "Pillow"),
            starts=("living-2", "bathroom-1"),
            odom_hz=2.0,
        )
        [result] = ingest([bag], lake_dir, robot=BAG_ROBOT)
        if result.error is not None:
            raise RuntimeError(f"ingesting the golden bag failed: {result.error}")


def bless(directory: Path) -> list[Path]:
    """Re-record every golden log (and the bag lake) under ``directory``; returns what was
    written."""
    written = []
    lake = directory / BAG_LAKE
    tmp_lake = directory / f".{BAG_LAKE}.tmp"
    shutil.rmtree(tmp_lake, ignore_errors=True)
    record_bag_lake(tmp_lake)
    shutil.rmtree(lake, ignore_errors=True)
    tmp_lake.rename(lake)
    written.append(lake)
    for run in GOLDEN_RUNS:
        target = directory / run.name
        tmp = directory / f".{run.name}.tmp"
        shutil.rmtree(tmp, ignore_errors=True)
        record(run, tmp)
        (tmp / "LOCK").unlink(missing_ok=True)
        shutil.rmtree(target, ignore_errors=True)
        tmp.rename(target)
        written.append(target)
    return written


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print(
            "usage: python -m objsearch.experiments.golden DIR  (make bless: tests/replay/golden)",
            file=sys.stderr,
        )
        return 2
    for path in bless(Path(args[0])):
        print(f"blessed {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
