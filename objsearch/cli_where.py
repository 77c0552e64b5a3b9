"""`objsearch where TARGET`: where the robot's memory says an object is."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from objsearch import cli_types as t


def register(sub: Any) -> None:
    where = sub.add_parser(
        "where", help="where an object was last seen, where it usually is, how sure (from a log)"
    )
    where.add_argument("target", metavar="TARGET", type=t.text, help="object class, e.g. Cup")
    where.add_argument("--log", required=True, type=t.existing_dir, help="event log folder")
    where.add_argument("--json", action="store_true", help="print the answer as JSON")
    where.set_defaults(func=cmd_where)


def cmd_where(args: argparse.Namespace) -> int:
    from objsearch.agent.where import render, where

    answer = where(Path(args.log), args.target)
    print(json.dumps(answer, indent=2) if args.json else render(answer))
    return 0
