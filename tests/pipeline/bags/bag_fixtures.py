"""Helpers shared by the bag tests."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from objsearch.agent.catalogue import STORE
from objsearch.events import Event, read_log
from objsearch.events.lake import TableLake
from objsearch.pipeline.bags.formats import BagFormat
from objsearch.pipeline.bags.lake import FleetBagLake
from objsearch.pipeline.bags.record import Recording, record

REPO_ROOT = Path(__file__).resolve().parents[3]

SHARED_BAGS = REPO_ROOT.parent / "shared" / "data" / "bags"


@dataclass(frozen=True)
class Recorded:
    bag: Path
    recording: Recording
    log: tuple[Event, ...]  # the agent's own log


def record_run(root: Path, fmt: BagFormat, **kwargs: object) -> Recorded:
    name = "run.bag" if fmt is BagFormat.ROS1 else "run"
    log_dir = root / "log"
    rec = record(
        root / name,
        fmt,
        scenes=[1],
        targets=["Apple", "Cup"],
        starts=["kitchen-1"],
        log_dir=log_dir,
        odom_hz=2.0,
        chunk_bytes=16 * 1024,  # several chunks, so damage tests can lose some and keep others
        **kwargs,  # type: ignore[arg-type]
    )
    return Recorded(root / name, rec, tuple(read_log(log_dir, store=STORE)))


#: A lake's bag runs (robot, date, rows per type, agent events) and the bags it knows.
Content = tuple[list[tuple[str, str, dict[str, int], list[tuple[str, int, str]]]], dict[str, str]]


def fleet(root: Path | str) -> str:
    """An empty fleet lake at ``root`` (as ingest's first commit would create it)."""
    TableLake(root, store=STORE).create()
    return str(root)


def content(root: Path | str) -> Content:
    """Each bag run (robot, date, rows per type, its agent events) and the bags the lake knows
    (bag id → converter)."""
    bags = FleetBagLake(root)
    lake = bags.lake
    runs = []
    for info in lake.runs():
        events = sorted(
            (e.event_id, e.time_ns, e.type)
            for e in lake.read_events(info)
            if not e.stream.startswith("bag:")
        )
        runs.append((info.robot, info.date, dict(info.rows), events))
    return sorted(runs), dict(bags.known_pieces())
