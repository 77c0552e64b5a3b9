"""`objsearch where TARGET`: where the robot's memory says an object is (a log or a lake run)."""

from __future__ import annotations

import argparse
import json
from typing import Any

from objsearch import cli_types as t


def register(sub: Any) -> None:
    where = sub.add_parser(
        "where",
        help="where an object was last seen, where it usually is, how sure (from a log or a lake)",
        description="Folds the events of an event log or of one lake run (with --run) "
        "with the memory model and answers from it; a log and the lake run made from it "
        "give the same answer. A lake holding several runs needs --run (objsearch lake ls lists "
        "them). The running agent answers the same question: objsearch agent where.",
    )
    where.add_argument("target", metavar="TARGET", type=t.text, help="object class, e.g. Cup")
    t.input_argument(
        where,
        "log",
        type=t.log_or_lake,
        metavar="LOG|LAKE",
        help="event log folder, or a lake (with --run): a folder or s3://bucket/prefix",
        old=("--log", "--lake"),
    )
    where.add_argument("--run", type=t.text, help="the lake run to answer from (with a lake)")
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
    t.format_option(where, "print the answer as JSON")
    t.progress_option(where)
    where.set_defaults(func=cmd_where)


def cmd_where(args: argparse.Namespace) -> int:
    from objsearch.agent.catalogue import DayClock
    from objsearch.agent.where import render, where
    from objsearch.replay.source import open_events

    events, _ = open_events(args.log, run=args.run, robot=args.robot)
    at = None if args.at is None else DayClock(weekday=args.at[0], minute=args.at[1])
    folding = t.progress(events, "where", " events", enabled=not args.no_progress)
    answer = where(folding, args.target, at=at)
    print(json.dumps(answer, indent=2) if args.format == "json" else render(answer))
    return 0
