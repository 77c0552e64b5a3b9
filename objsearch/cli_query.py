"""``objsearch query`` and ``objsearch lake``: the analytics lake from the command line."""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import decimal
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

DEFAULT_LAKE = "out/lake"
EXIT_USAGE = 2


def _default_lake() -> str:
    return os.environ.get("OBJSEARCH_LAKE", DEFAULT_LAKE)


def _fail(message: str) -> int:
    print(f"objsearch: error: {message}", file=sys.stderr)
    return EXIT_USAGE


def cmd_query(args: argparse.Namespace) -> int:
    import duckdb

    from objsearch.replay.analytics import open_analytics

    lake = Path(args.lake)
    if not lake.is_dir():
        return _fail(f"no lake at {lake} (add runs with `objsearch lake add LOG --lake {lake}`)")
    con = open_analytics(lake)
    try:
        result = con.execute(args.sql)
        names = [d[0] for d in result.description or ()]
        rows = result.fetchall()
    except duckdb.Error as exc:
        return _fail(f"query failed: {exc}")
    write_rows(names, rows, args.format, sys.stdout)
    return 0


def write_rows(names: Sequence[str], rows: Sequence[Sequence[Any]], fmt: str, out: Any) -> None:
    if fmt == "json":
        records = [dict(zip(names, map(_plain, row), strict=True)) for row in rows]
        json.dump(records, out, indent=1, ensure_ascii=False, allow_nan=False)
        out.write("\n")
    elif fmt == "csv":
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(names)
        for row in rows:
            writer.writerow(_cell(v) for v in row)
    else:
        cells = [[_cell(v) for v in row] for row in rows]
        widths = [max([len(n), *(len(r[i]) for r in cells)]) for i, n in enumerate(names)]
        out.write("  ".join(n.ljust(w) for n, w in zip(names, widths, strict=True)).rstrip() + "\n")
        out.write("  ".join("-" * w for w in widths) + "\n")
        for r in cells:
            out.write("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() + "\n")
        out.write(f"({len(rows)} row{'s' if len(rows) != 1 else ''})\n")


def _plain(value: Any) -> Any:
    """A JSON-able value: dates as ISO text, decimals as floats, NaN/inf as null."""
    if isinstance(value, dt.date | dt.datetime | dt.time):
        return value.isoformat()
    if isinstance(value, decimal.Decimal):
        return float(value)
    if isinstance(value, float) and (value != value or value in (float("inf"), float("-inf"))):
        return None
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, bytes):
        return value.hex()
    return value


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, str):
        return value
    if isinstance(value, float):
        return repr(value)
    return json.dumps(_plain(value), ensure_ascii=False)


def cmd_lake_add(args: argparse.Namespace) -> int:
    from objsearch.events.lake import Lake, compact_log

    info = compact_log(
        Path(args.log),
        Lake(args.lake),
        robot=args.robot,
        run=args.run,
        date=args.date,
        replace=args.replace,
    )
    if args.json:
        doc = {
            "path": str(info.path),
            "robot": info.robot,
            "date": info.date,
            "run": info.run,
            "events": info.events,
            "rows": dict(info.rows),
            "digest": info.digest,
            "source": info.source,
        }
        print(json.dumps(doc, indent=2))
        return 0
    print(f"{info.path}: {info.events} events in {len(info.rows)} tables ({info.digest[:19]}…)")
    return 0


def cmd_lake_upgrade(args: argparse.Namespace) -> int:
    from objsearch.events.lake import Lake

    lake = Path(args.lake)
    if not lake.is_dir():
        return _fail(f"no lake at {lake}")
    upgraded = Lake(lake).upgrade()
    for info in upgraded:
        print(f"{info.path}: derived tables written")
    print(f"{len(upgraded)} run(s) upgraded; every run now has the current derived tables")
    return 0


def cmd_lake_ls(args: argparse.Namespace) -> int:
    from objsearch.events.lake import Lake

    runs = Lake(args.lake).runs()
    rows = [(r.robot, r.date, r.run, r.events, r.source) for r in runs]
    write_rows(["robot", "date", "run", "events", "source"], rows, args.format, sys.stdout)
    return 0


def register(sub: Any) -> None:
    query = sub.add_parser(
        "query",
        help="run SQL (DuckDB) over the analytics lake",
        description="Views: one per event type (detection, plan_computed, …), events, searches, "
        "plans, detections, scene_graph; macros scene_graph_at_seq(s), scene_graph_at_time(t_ns). "
        "See docs/analytics.md.",
    )
    query.add_argument(
        "sql", help='the query, e.g. "SELECT target, avg(path_length) FROM searches GROUP BY 1"'
    )
    query.add_argument(
        "--lake", default=_default_lake(), help=f"lake folder ($OBJSEARCH_LAKE or {DEFAULT_LAKE})"
    )
    query.add_argument("--format", choices=["table", "csv", "json"], default="table")
    query.set_defaults(func=cmd_query)

    lake = sub.add_parser("lake", help="put event logs into the analytics lake, list what it holds")
    lake_sub = lake.add_subparsers(dest="lake_command", required=True, metavar="SUBCOMMAND")
    add = lake_sub.add_parser("add", help="compact a sealed event log into the lake as one run")
    add.add_argument("log", help="event log folder (its writer must have closed it)")
    add.add_argument("--robot", required=True, help="robot name (partition)")
    add.add_argument("--run", help="run name (default: the log's stream)")
    add.add_argument("--date", help="YYYY-MM-DD (default: the UTC day of the first event)")
    add.add_argument("--replace", action="store_true", help="replace the run if it differs")
    add.add_argument("--json", action="store_true", help="print the committed run as JSON")
    add.add_argument(
        "--lake", default=_default_lake(), help=f"lake folder ($OBJSEARCH_LAKE or {DEFAULT_LAKE})"
    )
    add.set_defaults(func=cmd_lake_add)
    ls = lake_sub.add_parser("ls", help="list the runs in the lake")
    ls.add_argument(
        "--lake", default=_default_lake(), help=f"lake folder ($OBJSEARCH_LAKE or {DEFAULT_LAKE})"
    )
    ls.add_argument("--format", choices=["table", "csv", "json"], default="table")
    ls.set_defaults(func=cmd_lake_ls)
    upgrade = lake_sub.add_parser(
        "upgrade",
        help="write the derived tables (searches, eq4_updates, scene_graph) that runs committed "
        "by older code lack; queries are correct without them, only slower",
    )
    upgrade.add_argument(
        "--lake", default=_default_lake(), help=f"lake folder ($OBJSEARCH_LAKE or {DEFAULT_LAKE})"
    )
    upgrade.set_defaults(func=cmd_lake_upgrade)
