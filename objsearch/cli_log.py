"""`objsearch log verify` and `objsearch log repair`: check a log, and the one way past damage."""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

from objsearch import cli_types as t


def register(sub: Any) -> None:
    log = sub.add_parser("log", help="check an event log end to end, or repair a damaged one")
    log_sub = log.add_subparsers(dest="log_command", required=True, metavar="SUBCOMMAND")

    verify = log_sub.add_parser(
        "verify",
        help="read and check every record (exit 0 clean, 2 damaged; nothing is changed)",
    )
    verify.add_argument("log", metavar="LOG", type=t.existing_dir, help="event log folder")
    verify.add_argument("--json", action="store_true", help="print the result as JSON")
    verify.set_defaults(func=cmd_log_verify)

    repair = log_sub.add_parser(
        "repair",
        help="cut a damaged log back to its clean prefix, keeping what is removed beside it",
        description="Converts CR LF line endings back when that makes the log clean; otherwise "
        "moves everything from the first damaged record on into events.log.repair-<offset> "
        "beside the log and keeps the clean prefix. Nothing is deleted. Reports acknowledged "
        "records the file had already lost (a log cut short before its high-water mark).",
    )
    repair.add_argument("log", metavar="LOG", type=t.existing_dir, help="event log folder")
    repair.add_argument("--json", action="store_true", help="print the result as JSON")
    repair.set_defaults(func=cmd_log_repair)


def _as_json(record: Any) -> str:
    return json.dumps(
        {k: str(v) if isinstance(v, Path) else v for k, v in dataclasses.asdict(record).items()},
        indent=2,
    )


def cmd_log_verify(args: argparse.Namespace) -> int:
    from objsearch.events.repair import verify_log

    result = verify_log(Path(args.log))
    if args.json:
        print(_as_json(result))
        return 0
    mark = (
        f"reaches its high-water mark (seq {result.durable_seq})"
        if result.durable_seq is not None
        else "no high-water mark (its writer never closed it cleanly)"
    )
    print(
        f"ok: {result.directory}: {result.events} events, seq 1..{result.last_seq}, "
        f"stream {result.stream!r}, {result.format}; {mark}"
    )
    if result.torn_bytes:
        print(
            f"note: {result.torn_bytes} byte(s) of an interrupted append follow the last record; "
            "the next writer keeps them aside in events.log.torn-<offset> and cuts them"
        )
    return 0


def cmd_log_repair(args: argparse.Namespace) -> int:
    from objsearch.events.repair import repair_log

    result = repair_log(Path(args.log))
    if args.json:
        print(_as_json(result))
        return 0
    if not result.changed:
        print(f"ok: {result.directory} is clean ({result.kept_events} events); nothing changed")
        return 0
    print(f"repaired {result.directory}: {result.problem}")
    if result.removed_bytes:
        print(
            f"  moved {result.removed_bytes} byte(s) ({result.removed_lines} line(s)) from the end "
            f"of events.log to {result.quarantine}"
        )
    elif result.quarantine is not None:
        print(f"  converted CR LF line endings back; the original is kept in {result.quarantine}")
    print(f"  the log keeps {result.kept_events} events (seq 1..{result.kept_last_seq})")
    if result.missing_seqs is not None:
        first, last = result.missing_seqs
        print(
            f"  acknowledged seqs {first}..{last} were already missing from the file; they "
            "cannot be recovered from this log"
        )
    return 0
