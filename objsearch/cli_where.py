"""`objsearch where TARGET`: where the robot's memory says an object is (a log or a lake run)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from objsearch import cli_types as t


def register(sub: Any) -> None:
    where = sub.add_parser(
        "where",
        help="where an object was last seen, where it usually is, how sure (from a log or a lake)",
        description="Folds the events of an event log (--log) or of one lake run (--lake, "
        "--run) with the memory model and answers from it; a log and the lake run made from it "
        "give the same answer. A lake holding several runs needs --run (objsearch lake ls lists "
        "them). The running agent answers the same question: objsearch agent where.",
    )
    where.add_argument("target", metavar="TARGET", type=t.text, help="object class, e.g. Cup")
    source = where.add_mutually_exclusive_group(required=True)
    source.add_argument("--log", type=t.existing_dir, help="event log folder")
    source.add_argument("--lake", type=t.existing_dir, help="a lake (objsearch lake add)")
    where.add_argument("--run", type=t.text, help="the lake run to answer from (with --lake)")
    where.add_argument(
        "--robot", type=t.text, help="the robot whose run it is, if run names repeat"
    )
    where.add_argument(
        "--at",
        type=t.day_time,
        default="now",
        help="the time of the week to answer for: now (default, the local clock), HH:MM (today), "
        "DAY HH:MM (DAY mon…sun), or last (the time of the log's latest search); a log whose "
        "searches record no time of day gets the same answer at every time",
    )
    where.add_argument("--json", action="store_true", help="print the answer as JSON")
    where.set_defaults(func=cmd_where)


def cmd_where(args: argparse.Namespace) -> int:
    from objsearch.agent.errors import ObjsearchError
    from objsearch.agent.where import render, where
    from objsearch.replay.source import is_log, open_events

    path = Path(args.log or args.lake)
    if args.log is not None and not is_log(path):
        raise ObjsearchError(f"{path} is not an event log (no meta.json); if it is a lake: --lake")
    if args.lake is not None and is_log(path):
        raise ObjsearchError(f"{path} is an event log, not a lake: use --log")
    from objsearch.agent.catalogue import DayClock

    events, _ = open_events(path, run=args.run, robot=args.robot)
    at = None if args.at is None else DayClock(weekday=args.at[0], minute=args.at[1])
    answer = where(events, args.target, at=at)
    print(json.dumps(answer, indent=2) if args.json else render(answer))
    return 0
