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
    t.format_option(verify, "print the result as JSON")
    t.progress_option(verify)
    verify.set_defaults(func=cmd_log_verify)

    repair = log_sub.add_parser(
        "repair",
        help="take only the damage out of a log, keeping what is removed beside it",
        description="Converts CR LF line endings back. Each record is found by its witnesses, "
        "not by where it stands: the next record is the line whose checksum was chained from "
        "the last one kept, so blank, duplicated, inserted or swapped lines cost no record. A "
        "damaged record is judged by its witnesses (the next record, the high-water mark): a "
        "flipped bit is corrected, damaged checksum digits are rewritten, a record damaged "
        "otherwise is replaced by a record_quarantined event at its seq; after lines lost or "
        "damaged beyond that, the next intact record of this log (its own id, its checksum "
        "proven) resumes it. What no witness places is moved out to "
        "events.log.repair-<offset> beside the log; nothing is deleted, and removed or lost "
        "seqs stay taken, so no later event reuses their ids. Refuses (exit 2, nothing "
        "changed) a meta.json the records prove edited. Prints every change, with its line, "
        "byte offset and reason.",
    )
    repair.add_argument("log", metavar="LOG", type=t.existing_dir, help="event log folder")
    t.format_option(repair, "print the result as JSON")
    t.progress_option(repair)
    repair.set_defaults(func=cmd_log_repair)


def _as_json(record: Any) -> str:
    return json.dumps(
        {k: str(v) if isinstance(v, Path) else v for k, v in dataclasses.asdict(record).items()},
        indent=2,
    )


def cmd_log_verify(args: argparse.Namespace) -> int:
    from objsearch.events.repair import verify_log
    from objsearch.product import STORE

    result = verify_log(
        Path(args.log),
        store=STORE,
        progress=lambda records: t.progress(
            records, "log verify", " records", enabled=not args.no_progress
        ),
    )
    if args.format == "json":
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
    from objsearch.product import STORE

    result = repair_log(
        Path(args.log),
        store=STORE,
        progress=lambda items: t.progress(
            items, "log repair", " records", enabled=not args.no_progress
        ),
    )
    if args.format == "json":
        print(_as_json(result))
        return 0
    if not result.changed:
        print(f"ok: {result.directory} is clean ({result.kept_events} events); nothing changed")
        return 0
    print(f"repaired {result.directory}: {result.problem}")
    for action in result.actions:
        seqs = (
            f"seq {action.first_seq}"
            if action.first_seq == action.last_seq
            else f"seqs {action.first_seq}..{action.last_seq}"
        )
        what = _ACTION_WORDS[action.kind]
        print(f"  {seqs} (line {action.line}, byte {action.offset}): {what}: {action.reason}")
    if result.removed_bytes:
        print(
            f"  {result.removed_bytes} byte(s) ({result.removed_lines} line(s)) taken out of "
            f"events.log are kept in {result.quarantine}"
        )
    elif result.quarantine is not None:
        print(f"  converted CR LF line endings back; the original is kept in {result.quarantine}")
    print(
        f"  the log keeps {result.kept_events} events; it ends at seq {result.kept_last_seq} "
        "(removed and lost seqs stay taken by record_quarantined events)"
    )
    return 0


_ACTION_WORDS = {
    "checksum-rewritten": "checksum rewritten, record kept",
    "bit-restored": "flipped bit corrected, record kept",
    "line-ending-restored": "line ending converted back, record kept",
    "byte-restored": "a byte overwritten by a newline restored, record kept",
    "reordered": "record kept, put back in its order",
    "quarantined": "moved out, its seq(s) kept by record_quarantined events",
    "extra": "moved out (no record of this log at this place; no seq lost)",
    "lost": "missing from the file; the seqs are kept by record_quarantined events",
    "cut": "moved out with everything after it",
    "missing": "already missing from the file, cannot be recovered",
}
