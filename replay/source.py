"""Where replay, audit and ``where`` read events from: an agent's log folder, or one run of the
fleet lake (one Delta table, in a folder or at an ``s3://`` address). A per-run-folder lake is
refused: ``objsearch lake upgrade`` migrates it."""

from __future__ import annotations

import contextlib
from collections.abc import Iterable, Iterator
from pathlib import Path

from objsearch.agent.catalogue import STORE
from objsearch.agent.errors import ObjsearchError
from objsearch.events import Event, read_log
from objsearch.events.lake import NoLakeError, TableRun, is_table_lake, open_lake
from objsearch.events.lake.run_read import RunReader


def is_log(path: Path) -> bool:
    return (path / "meta.json").exists()


def _one_run(
    runs: list[TableRun], where: Path | str, *, run: str | None, robot: str | None
) -> TableRun:
    """The one of a lake's ``runs`` that ``run`` / ``robot`` select, or an error that says what
    there is to choose from."""
    chosen = [
        r for r in runs if (run is None or r.run == run) and (robot is None or r.robot == robot)
    ]
    if len(chosen) == 1:
        return chosen[0]
    available = ", ".join(f"{r.robot}/{r.run}" for r in runs) or "none"
    if not chosen and run is None and robot is None:
        raise ObjsearchError(
            f"the lake {where} holds no runs; add a run with "
            f"`objsearch lake add LOG --lake {where}`"
        )
    if not chosen:
        raise ObjsearchError(
            f"no run {run!r}{f' of robot {robot!r}' if robot else ''} in the lake {where} "
            f"(runs: {available})"
        )
    raise ObjsearchError(
        f"the lake {where} holds several runs ({available}); choose one with --run"
    )


def _agent_stream(streams: Iterable[str]) -> str:
    found = sorted(streams)
    if not found:
        raise ObjsearchError("the run holds no agent events (no run_started)")
    if len(found) > 1:
        raise ObjsearchError(f"the run holds several agent streams: {', '.join(found)}")
    return found[0]


def table_lake_stream(
    where: Path | str, *, run: str | None = None, robot: str | None = None
) -> tuple[Iterator[Event], TableRun]:
    """The agent's events of the one run of the fleet lake at ``where`` that ``run`` / ``robot``
    select, streamed: every row of the run is read and checked against what its commit
    recorded before the first event is handed out, then read again a few thousand rows at a
    time (:class:`~objsearch.events.lake.run_read.RunReader`), so a fold from a lake run costs
    about the memory of a fold from its log."""
    lake = open_lake(where, store=STORE)
    table = lake.listing()  # its log's files, without delta-rs where the log allows
    info = _one_run(lake.runs(table), where, run=run, robot=robot)
    reader = RunReader(lake, info, table)
    reader.check()
    stream = _agent_stream(reader.streams.get("run_started", ()))
    return reader.events([stream]), info


def open_events(
    location: Path | str, *, run: str | None = None, robot: str | None = None
) -> tuple[list[Event] | Iterable[Event], str]:
    """Events of a log folder (streamed) or of one lake run, and a name for reports.
    ``location``: a folder, or a fleet lake's ``s3://bucket/prefix``."""
    if "://" in str(location) or is_table_lake(location):
        events, committed = table_lake_stream(location, run=run, robot=robot)
        return events, f"{location} ({committed.robot}/{committed.run})"
    path = Path(location)
    if not path.exists():
        raise ObjsearchError(f"no log or lake at {path}")
    if is_log(path):
        if run is not None or robot is not None:
            raise ObjsearchError(f"{path} is an event log, not a lake: --run/--robot do not apply")
        return read_log(path, store=STORE), str(path)
    with contextlib.suppress(NoLakeError):  # a per-run-folder lake is refused, naming its migration
        open_lake(path, store=STORE, existing=True)
    raise ObjsearchError(f"{path} is neither an event log (no meta.json) nor a lake")
