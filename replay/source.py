"""Where replay and audit read events from: an agent's log folder, or one run of a lake."""

from __future__ import annotations

import logging
from collections.abc import Iterable
from pathlib import Path

from objsearch.agent.catalogue import STORE
from objsearch.agent.errors import ObjsearchError
from objsearch.events import Event, read_log
from objsearch.events.lake import Lake, RunInfo, deep_check

_log = logging.getLogger(__name__)


def is_log(path: Path) -> bool:
    return (path / "meta.json").exists()


def lake_run(path: Path, *, run: str | None = None, robot: str | None = None) -> RunInfo:
    """The one run of the lake at ``path`` that ``run`` / ``robot`` select; damaged runs are
    left out with a warning, and selecting one is an error that names it."""
    lake = Lake(path, store=STORE)
    if lake.needs_recovery():
        lake.recover()
    healthy, damaged = lake.scan()
    for bad in damaged:
        if (
            run is not None
            and bad.path.name == f"run={run}"
            and (robot is None or bad.path.parent.parent.name == f"robot={robot}")
        ):
            raise ObjsearchError(f"run {run!r} in the lake {path} is damaged: {bad.reason}")
        _log.warning("%s: damaged run left out: %s", bad.path, bad.reason)
    runs = [
        r for r in healthy if (run is None or r.run == run) and (robot is None or r.robot == robot)
    ]
    if len(runs) == 1:
        problem = deep_check(runs[0])
        if problem is not None:
            raise ObjsearchError(f"run {runs[0].run!r} in the lake {path} is damaged: {problem}")
        return runs[0]
    available = ", ".join(f"{r.robot}/{r.run}" for r in healthy) or "none"
    if not runs and run is None and robot is None:
        raise ObjsearchError(
            f"the lake {path} holds no runs; add a run with `objsearch lake add LOG --lake {path}`"
        )
    if not runs:
        raise ObjsearchError(
            f"no run {run!r}{f' of robot {robot!r}' if robot else ''} in the lake {path} "
            f"(runs: {available})"
        )
    raise ObjsearchError(f"the lake {path} holds several runs ({available}); choose one with --run")


def agent_events(events: Iterable[Event]) -> list[Event]:
    """The agent's own stream of a lake run (a bag's run also holds the poses and detections the
    pipeline derived from other topics, in streams of their own)."""
    events = list(events)
    streams = sorted({e.stream for e in events if e.type == "run_started"})
    if not streams:
        raise ObjsearchError("the run holds no agent events (no run_started)")
    if len(streams) > 1:
        raise ObjsearchError(f"the run holds several agent streams: {', '.join(streams)}")
    return [e for e in events if e.stream == streams[0]]


def open_events(
    path: Path, *, run: str | None = None, robot: str | None = None
) -> tuple[list[Event] | Iterable[Event], str]:
    """Events of a log folder (streamed) or of one lake run, and a name for reports."""
    if not path.exists():
        raise ObjsearchError(f"no log or lake at {path}")
    if is_log(path):
        if run is not None or robot is not None:
            raise ObjsearchError(f"{path} is an event log, not a lake: --run/--robot do not apply")
        return read_log(path, store=STORE), str(path)
    info = lake_run(path, run=run, robot=robot)
    return agent_events(
        Lake(path, store=STORE).read_events(info)
    ), f"{path} ({info.robot}/{info.run})"
