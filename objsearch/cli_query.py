"""``objsearch query`` and ``objsearch lake``: the analytics lake from the command line."""

from __future__ import annotations

import argparse
import codecs
import csv
import datetime as dt
import decimal
import json
import math
import os
import re
import sys
import uuid
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from objsearch import cli_types as t
from objsearch.agent.errors import ObjsearchError
from objsearch.events.sql_limits import (
    DEFAULT_MEMORY_LIMIT,
    DEFAULT_TIMEOUT_S,
    MAX_MEMORY_LIMIT,
    MIN_MEMORY_LIMIT,
    format_size,
)

if TYPE_CHECKING:
    from objsearch.events.lake import TableLake

DEFAULT_LAKE = "out/lake"
EXIT_USAGE = 2
MAX_TIMEOUT_S = 86_400.0


def _default_lake() -> str:
    return os.environ.get("OBJSEARCH_LAKE", DEFAULT_LAKE)


def _fail(message: str) -> int:
    print(f"objsearch: error: {message}", file=sys.stderr)
    return EXIT_USAGE


def cmd_query(args: argparse.Namespace) -> int:
    import duckdb

    from objsearch.events.sql_limits import QueryLimitError
    from objsearch.replay.query_process import QueryProcess, QueryRequest

    lake = Path(args.lake)
    remote = _remote(args.lake)
    if not remote and not lake.is_dir():
        return _fail(
            f"no lake at {lake} (add runs with `objsearch lake add LOG --robot NAME --lake {lake}`)"
        )
    out = Path(args.out) if args.out is not None else None
    if out is not None:
        if not args.out.strip():
            return _fail("--out needs a file path")
        if not remote and out.resolve().is_relative_to(lake.resolve()):
            return _fail(f"--out {args.out} is inside the lake {lake}; write results elsewhere")
        try:
            _check_out(out, force=args.force)
        except OutputRefusedError as exc:
            return _fail(str(exc))
    elif args.force:
        return _fail("--force replaces the file --out names; there is no --out")
    if not args.sql.strip():
        return _fail('no SQL given (e.g. "SELECT count(*) FROM events")')
    # DuckDB's work and the fetch of its rows run in a process capped in memory and killed at
    # the time limit (replay/query_process.py); the rows are written here
    request = QueryRequest(
        lake=args.lake if remote else str(lake),
        sql=args.sql,
        memory_limit=args.memory_limit,
        timeout_s=args.timeout,
        # a table is laid out from every row: they count against the memory limit together
        holds_all=args.format == "table",
    )
    try:
        with QueryProcess(request) as result:
            if out is None:
                write_batches(result.names, result, args.format, sys.stdout, check=result.check)
                return 0
            rows = _write_file(
                out, result.names, result, args.format, force=args.force, check=result.check
            )
    except QueryLimitError as exc:
        return _fail(str(exc))
    except duckdb.Error as exc:
        return _fail(f"query failed: {lake_names_hint(str(exc))}")
    except (ResultTooLargeError, OutputRefusedError) as exc:
        return _fail(str(exc))
    except OSError as exc:
        if out is None or exc.filename is None:
            raise
        return _fail(f"cannot write --out {args.out}: {exc.strerror or exc}")
    print(f"wrote {rows} row{'s' if rows != 1 else ''} to {out}", file=sys.stderr)
    return 0


#: ``query`` and ``lake ls`` print tables: ``--format table|csv|json``.
TABLE_FORMATS = ("table", "csv", "json")
#: Rows ``--format table`` holds to size its columns; csv and json stream any number.
TABLE_MAX_ROWS = 100_000


class ResultTooLargeError(Exception):
    """A result too long to lay out as a table."""


class OutputRefusedError(Exception):
    """``--out`` names something ``query`` does not write over."""


def _check_out(out: Path, *, force: bool) -> None:
    """Raise :class:`OutputRefusedError` unless ``out`` is free, or (with ``force``) a regular
    file: a link, a FIFO, a device or a folder is never written through nor replaced."""
    import stat

    from objsearch.events._fs import describe_mode

    try:
        mode = os.lstat(out).st_mode
    except FileNotFoundError:
        return
    if not stat.S_ISREG(mode):
        raise OutputRefusedError(
            f"--out {out} is {describe_mode(mode)}, not a regular file; query writes only "
            "regular files (nothing was written)"
        )
    if not force:
        raise OutputRefusedError(f"--out {out} already exists; pass --force to replace it")


def _write_file(
    out: Path,
    names: Sequence[str],
    batches: Iterable[Sequence[Sequence[Any]]],
    fmt: str,
    *,
    force: bool,
    check: Callable[[], None] | None = None,
) -> int:
    """Stream the result into a new hidden file beside ``out`` (``O_CREAT | O_EXCL |
    O_NOFOLLOW``), then put it at ``out``: a query stopped halfway leaves no file, and nothing
    but a regular file is ever replaced (without ``force``, nothing at all: the file is linked
    into place, which fails if anything appeared there meanwhile)."""
    import secrets

    from objsearch.events._fs import fsync_dir

    tmp = out.with_name(f".{out.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC
    fd = os.open(tmp, flags, 0o666)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
            rows = write_batches(names, batches, fmt, fh, check=check)
            fh.flush()
            os.fsync(fh.fileno())
        _place(tmp, out, force=force)
    finally:
        tmp.unlink(missing_ok=True)
    fsync_dir(out.parent, step=False)
    return rows


def _place(tmp: Path, out: Path, *, force: bool) -> None:
    """Put the finished ``tmp`` at ``out``, as :func:`_check_out` allows, checked again now."""
    import errno

    if not force:
        try:
            os.link(tmp, out)  # never replaces: EEXIST if anything is at out, a dangling link too
            return
        except FileExistsError:
            _check_out(out, force=False)  # says what is there
            raise
        except OSError as exc:  # a file system without hard links: checked, then renamed
            if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EMLINK):
                raise
    _check_out(out, force=force)
    os.replace(tmp, out)


def write_batches(
    names: Sequence[str],
    batches: Iterable[Sequence[Sequence[Any]]],
    fmt: str,
    out: Any,
    *,
    check: Callable[[], None] | None = None,
) -> int:
    """Write a result that arrives in batches; csv and json as they come, a table at the end
    (at most :data:`TABLE_MAX_ROWS` rows). ``check`` is called as the table is written (it
    raises to stop: the query's time limit). Returns the number of rows."""
    if fmt == "table":
        rows: list[Sequence[Any]] = []
        for batch in batches:
            rows.extend(batch)
            if len(rows) > TABLE_MAX_ROWS:
                raise ResultTooLargeError(
                    f"the result has more than {TABLE_MAX_ROWS:,} rows, too many to lay out as "
                    "a table; use --format csv or json (they stream), or add a LIMIT"
                )
        write_rows(names, rows, fmt, out, check=check)
        return len(rows)
    count = 0
    if fmt == "json":
        # JSON escapes what the output cannot encode (an ASCII-only stdout would otherwise get
        # backslash escapes that are not JSON).
        ascii_only = not _writes_utf8(out)
        out.write("[")
        for batch in batches:
            for row in batch:
                record = dict(zip(names, map(_plain, row), strict=True))
                out.write(",\n" if count else "\n")
                out.write(json.dumps(record, ensure_ascii=ascii_only, allow_nan=False))
                count += 1
        out.write("\n]\n")
        return count
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(names)
    for batch in batches:
        for row in batch:
            writer.writerow(_cell(v) for v in row)
            count += 1
    return count


def _writes_utf8(out: Any) -> bool:
    """Whether text written to ``out`` reaches its bytes as UTF-8 (a StringIO, or a file this
    module opened as UTF-8, has no encoding of its own: the caller encodes it as UTF-8)."""
    encoding = getattr(out, "encoding", None)
    if not encoding:
        return True
    try:
        return codecs.lookup(encoding).name == "utf-8"
    except LookupError:
        return False


def write_rows(
    names: Sequence[str],
    rows: Sequence[Sequence[Any]],
    fmt: str,
    out: Any,
    *,
    check: Callable[[], None] | None = None,
) -> None:
    if fmt in ("json", "csv"):
        write_batches(names, [rows], fmt, out)
        return
    cells = [[_cell(_rounded(v)) for v in row] for row in rows]
    widths = [max([len(n), *(len(r[i]) for r in cells)]) for i, n in enumerate(names)]
    out.write("  ".join(n.ljust(w) for n, w in zip(names, widths, strict=True)).rstrip() + "\n")
    out.write("  ".join("-" * w for w in widths) + "\n")
    for r in cells:
        if check is not None:
            check()
        out.write("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() + "\n")
    out.write(f"({len(rows)} row{'s' if len(rows) != 1 else ''})\n")


#: Significant digits of a float in a table (csv and json keep every digit).
TABLE_DIGITS = 6


def _rounded(value: Any) -> Any:
    """A float for a person to read: ``TABLE_DIGITS`` significant digits, but every digit of its
    whole part (17.909299999999998 → 17.9093, 1234567.891 → 1234568.0, 1.23456789e-07 stays
    small: 1.23457e-07); the floats in a list, map or struct too (a plan's candidates, its
    terms). A DECIMAL is exact and keeps the digits of its type."""
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_rounded(v) for v in value]
    if not isinstance(value, float) or not math.isfinite(value) or value == 0:
        return value
    whole = math.floor(math.log10(abs(value))) + 1
    if whole > 0:
        return round(value, max(0, TABLE_DIGITS - whole))
    return float(f"{value:.{TABLE_DIGITS}g}")


_NO_SUCH_TABLE = re.compile(
    r'Table with name (?P<name>[^\s!]+) does not exist!(?P<guess>\nDid you mean "[^"\n]*"\?)?'
)


def lake_names_hint(message: str) -> str:
    """DuckDB's error, its guess at a misspelt table taken from the lake's views: a query's
    connection holds only the views the query names, so DuckDB guessed from its own catalogue
    (``serches``: "Did you mean "sqlite_schema"?")."""
    found = _NO_SUCH_TABLE.search(message)
    if found is None:
        return message
    import difflib

    from objsearch.replay.analytics import queryable_names

    names = queryable_names()
    close = difflib.get_close_matches(found["name"].lower(), names, n=3, cutoff=0.6)
    guess = "Did you mean " + " or ".join(f'"{n}"' for n in close) + "? " if close else ""
    return (
        f"{message[: found.start()]}Table with name {found['name']} does not exist!\n{guess}"
        f"The lake's views and table macros: {', '.join(names)}{message[found.end() :]}"
    )


def _plain(value: Any) -> Any:
    """A JSON-able value: dates as ISO text, decimals as floats, NaN/inf as null, intervals as
    seconds, UUIDs and anything else DuckDB may return as text."""
    if value is None or isinstance(value, bool | int | str):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dt.date | dt.datetime | dt.time):
        return value.isoformat()
    if isinstance(value, dt.timedelta):
        return value.total_seconds()
    if isinstance(value, decimal.Decimal):
        return _plain(float(value))
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, bytes | bytearray | memoryview):
        return bytes(value).hex()
    if isinstance(value, uuid.UUID):
        return str(value)
    return str(value)


def _cell(value: Any) -> str:
    """One value as text for a table or CSV cell: scalars as themselves (no JSON quotes),
    nested values as JSON."""
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, dt.timedelta):
        return str(value)
    plain = _plain(value)
    if isinstance(plain, str):
        return plain
    return json.dumps(plain, ensure_ascii=False)


def _remote(lake: str) -> bool:
    return "://" in lake


def _existing_lake(where: str) -> TableLake:
    """The fleet lake at ``where``, or an error (a per-run-folder lake gets the migration's
    command: :func:`~objsearch.events.lake.open_lake`); warn of old run folders beside its
    table."""
    from objsearch.events.lake import open_lake
    from objsearch.events.lake.folder_v1 import is_folder_lake, left_run_folders
    from objsearch.product import STORE

    lake = open_lake(where, store=STORE, existing=True)
    if not lake.remote and is_folder_lake(where):  # what `lake upgrade` left: said, not hidden
        left = left_run_folders(where)
        print(
            f"objsearch: warning: {where} also holds {len(left)} run folder(s) of the old "
            f"per-run-folder format that `lake upgrade` left in place (damaged, or a run the "
            f"table already held), e.g. {left[0] if left else Path(where) / '.staging'}; no "
            "command reads them",
            file=sys.stderr,
        )
    return lake


def cmd_lake_add(args: argparse.Namespace) -> int:
    try:
        return _lake_add(args)
    except ObjsearchError as exc:
        # The lake speaks Python (replace=True); say it with this command's flags.
        text = str(exc).replace(
            "pass replace=True to replace it",
            "pass --replace to replace it, or --run NAME to add this log as another run",
        )
        if text == str(exc):
            raise
        raise ObjsearchError(text) from exc


def _lake_add(args: argparse.Namespace) -> int:
    from objsearch.events.lake import add_log, open_lake
    from objsearch.pipeline.bags.lake import refuse_a_log_a_session_holds
    from objsearch.product import STORE

    lake = open_lake(args.lake, store=STORE)
    refuse_a_log_a_session_holds(Path(args.log), args.lake)
    info = add_log(
        Path(args.log),
        lake,
        robot=args.robot,
        run=args.run,
        date=args.date,
        replace=args.replace,
        progress=lambda events: t.progress(
            events, "lake add", " events", enabled=not args.no_progress
        ),
    )
    if args.format == "json":
        doc = {
            "lake": str(args.lake),
            "robot": info.robot,
            "date": info.date,
            "run": info.run,
            "commit": info.commit,
            "events": info.events,
            "rows": dict(info.rows),
            "digest": info.digest,
            "source": info.source,
        }
        print(json.dumps(doc, indent=2))
        return 0
    print(
        f"{args.lake}: run {info.robot}/{info.run}: {info.events} events in {len(info.rows)} "
        f"tables ({info.digest[:19]}…)"
    )
    return 0


def cmd_lake_compact(args: argparse.Namespace) -> int:
    done = _existing_lake(args.lake).compact(vacuum_hours=args.keep_hours)
    print(
        f"{args.lake}: {done['files_before']} data file(s) → {done['files_after']}; "
        f"{done['vacuumed']} unreferenced file(s) deleted"
    )
    return 0


def cmd_lake_upgrade(args: argparse.Namespace) -> int:
    """Copy a per-run-folder lake's runs into a fleet table in the same folder (or --into)."""
    import contextlib
    import shutil

    from objsearch.events.lake import TABLE_FORMAT, TableLake, is_table_lake, open_lake
    from objsearch.events.lake.folder_v1 import is_folder_lake, migrate
    from objsearch.pipeline.bags.ledger import BagLedger
    from objsearch.product import STORE

    source = Path(args.lake)
    target = args.into or args.lake
    if _remote(args.lake):
        return _fail(
            "--lake of an upgrade is a local per-run-folder lake; name the bucket with --into"
        )
    if not source.is_dir():
        if args.into is not None:
            return _fail(f"no lake at {source}")
        TableLake(target, store=STORE).create()  # a new, empty fleet lake
        print(f"{target}: created an empty fleet lake")
        return 0
    if not is_folder_lake(source):
        if is_table_lake(source) and args.into is None:
            print(f"{source}: already a fleet lake ({TABLE_FORMAT}); nothing to upgrade")
            return 0
        return _fail(f"{source} holds no per-run-folder lake to upgrade")
    # The one command that opens a per-run-folder lake's folder as a fleet lake (it writes the
    # table beside the old runs); --into is opened as every command opens a lake.
    fleet = TableLake(target, store=STORE) if args.into is None else open_lake(target, store=STORE)
    done = migrate(
        source,
        fleet,
        bags=BagLedger(fleet),
        progress=lambda runs: t.progress(
            runs, "lake upgrade", " runs", enabled=not args.no_progress
        ),
    )
    for bad in done.damaged:
        print(
            f"objsearch: warning: damaged run not copied, left in place: {bad.path}: {bad.reason}",
            file=sys.stderr,
        )
    for path in done.already:
        print(
            f"objsearch: warning: {path}: not copied, the fleet table holds a run of that robot "
            "and name already; its folder is left in place",
            file=sys.stderr,
        )
    if args.into is None:
        # The copied runs live in the table now; their folders are what older code read.
        for folder in done.copied:
            shutil.rmtree(folder)
            for parent in (folder.parent, folder.parent.parent):
                with contextlib.suppress(OSError):  # not empty: other runs are in it
                    parent.rmdir()
        # What the old writer kept beside the runs: its pid hint, its (empty) staging folder.
        (source / ".writer").unlink(missing_ok=True)
        with contextlib.suppress(OSError):  # not empty: a commit it never finished, left as is
            (source / ".staging").rmdir()
    print(
        f"{target}: {len(done.copied)} run(s) copied into the fleet table "
        f"({len(fleet.runs())} in all)"
        + ("" if args.into is not None or not done.copied else "; their folders removed")
        + (f"; {len(done.damaged)} damaged run(s) left in place" if done.damaged else "")
        + (f"; {len(done.already)} already there, left in place" if done.already else "")
    )
    return EXIT_USAGE if done.damaged else 0


def cmd_lake_verify(args: argparse.Namespace) -> int:
    if args.lake_dir is not None and args.lake is not None and args.lake_dir != args.lake:
        return _fail(f"two lakes given ({args.lake_dir} and --lake {args.lake}); give one")
    where = args.lake_dir or args.lake or _default_lake()
    return _verify_fleet(_existing_lake(where), where, args.format == "json", not args.no_progress)


def _verify_fleet(lake: TableLake, where: str, as_json: bool, progress: bool) -> int:
    import time

    started = time.perf_counter()
    check = lake.verify(
        progress=lambda files: t.progress(files, "lake verify", " files", enabled=progress)
    )
    seconds = time.perf_counter() - started
    if as_json:
        doc = {
            "lake": where,
            "runs": check.runs,
            "files_checked": check.files,
            "bytes_checked": check.bytes,
            "seconds": round(seconds, 3),
            "damaged": [{"file": f, "problems": [why]} for f, why in check.damaged],
            "runs_damaged": [{"run": r, "problems": [why]} for r, why in check.runs_damaged],
        }
        print(json.dumps(doc, indent=2))
    else:
        for name, why in check.damaged:
            print(f"DAMAGED  {name}: {why}")
        for name, why in check.runs_damaged:
            print(f"DAMAGED  {'' if name.startswith('_') else 'run '}{name}: {why}")
        print(
            f"{check.runs} run(s), {check.files} file(s), {check.bytes / 1e6:.1f} MB checked in "
            f"{seconds:.2f} s; {len(check.runs_damaged)} disagreement(s) between the runs' "
            f"records and the table; {len(check.damaged)} damaged file(s)"
        )
    said = []
    if check.damaged:
        said.append(f"{len(check.damaged)} damaged data file(s) in {where}; queries leave them out")
    if check.runs_damaged:
        said.append(
            f"{len(check.runs_damaged)} disagreement(s) between the runs' records and the "
            f"table's log of {where}; queries refuse the lake"
        )
    if said:
        return _fail(f"{'; '.join(said)} (see docs/analytics.md)")
    return 0


def cmd_lake_ls(args: argparse.Namespace) -> int:
    fleet = _existing_lake(args.lake)  # as query says: listing nothing would hide a wrong path
    # refuses a table that does not hold what its runs recorded; lists past a damaged `_run`
    # file, then says which runs it could not list
    table = fleet.table()
    fleet.check_runs(table)
    runs, unreadable = fleet.read_runs(table)
    rows = [(r.robot, r.date, r.run, r.events, r.source) for r in runs]
    write_rows(["robot", "date", "run", "events", "source"], rows, args.format, sys.stdout)
    if unreadable:
        return _fail(
            f"the runs recorded in {len(unreadable)} damaged `_run` file(s) are not listed: "
            + "; ".join(why for _, why in unreadable)
            + f" (`objsearch lake verify {args.lake}` lists every damaged file)"
        )
    return 0


def _add_query(sub: Any) -> None:
    query = sub.add_parser(
        "query",
        help="run SQL (DuckDB) over the analytics lake",
        description="Views: one per event type (detection, plan_computed, …), events, searches, "
        "plans, detections, scene_graph; macros scene_graph_at_seq(s), scene_graph_at_time(t_ns). "
        "See docs/analytics.md.",
    )
    query.add_argument(
        "sql",
        type=t.sql,
        help='the query, e.g. "SELECT target, avg(path_length) FROM searches GROUP BY 1"',
    )
    query.add_argument(
        "--lake",
        default=_default_lake(),
        type=t.dir_path,
        help=f"lake folder ($OBJSEARCH_LAKE or {DEFAULT_LAKE})",
    )
    t.format_option(query, "the rows as a JSON array", choices=TABLE_FORMATS)
    query.add_argument(
        "--out",
        metavar="PATH",
        type=t.file_path,
        help="write the result to this new file (not inside the lake) instead of stdout; SQL "
        "itself cannot write files",
    )
    query.add_argument(
        "--force",
        action="store_true",
        help="with --out: replace the file if it exists (a regular file only: never a link, "
        "FIFO, device or folder)",
    )
    query.add_argument(
        "--timeout",
        type=t.float_range(0.0, MAX_TIMEOUT_S, lo_open=True),
        default=DEFAULT_TIMEOUT_S,
        metavar="SECONDS",
        help=f"stop the query after this long ({DEFAULT_TIMEOUT_S:g}; at most one day)",
    )
    query.add_argument(
        "--memory-limit",
        type=t.byte_size(MIN_MEMORY_LIMIT, MAX_MEMORY_LIMIT),
        default=DEFAULT_MEMORY_LIMIT,
        metavar="SIZE",
        help=f"DuckDB's memory for the query, e.g. 512MB, 4GiB ({format_size(DEFAULT_MEMORY_LIMIT)}); "
        "beyond it large sorts and joins spill to a private temp folder, others stop",
    )
    query.set_defaults(func=cmd_query)


def _add_add(lake_sub: Any) -> None:
    add = lake_sub.add_parser("add", help="compact a sealed event log into the lake as one run")
    add.add_argument(
        "log",
        type=t.existing_dir,
        metavar="LOG",
        help="event log folder (its writer must have closed it)",
    )
    add.add_argument("--robot", required=True, type=t.text, help="robot name (partition)")
    add.add_argument("--run", type=t.text, help="run name (default: the log's stream)")
    add.add_argument(
        "--date", type=t.date, help="YYYY-MM-DD (default: the UTC day of the first event)"
    )
    add.add_argument("--replace", action="store_true", help="replace the run if it differs")
    t.progress_option(add)
    t.format_option(add, "print the committed run as JSON")
    add.add_argument(
        "--lake",
        default=_default_lake(),
        type=t.dir_path,
        help=f"lake folder ($OBJSEARCH_LAKE or {DEFAULT_LAKE})",
    )
    add.set_defaults(func=cmd_lake_add)


def _add_ls(lake_sub: Any) -> None:
    ls = lake_sub.add_parser("ls", help="list the runs in the lake")
    ls.add_argument(
        "--lake",
        default=_default_lake(),
        type=t.dir_path,
        help=f"lake folder ($OBJSEARCH_LAKE or {DEFAULT_LAKE})",
    )
    t.format_option(ls, "the runs as a JSON array", choices=TABLE_FORMATS)
    ls.set_defaults(func=cmd_lake_ls)


def _add_verify(lake_sub: Any) -> None:
    verify = lake_sub.add_parser(
        "verify",
        help="read every file of every run and check it against the digest its commit recorded; "
        "exit 2 naming each damaged file",
    )
    verify.add_argument(
        "lake_dir",
        nargs="?",
        type=t.dir_path,
        metavar="LAKE",
        help=f"lake folder (or --lake; $OBJSEARCH_LAKE or {DEFAULT_LAKE})",
    )
    verify.add_argument(
        "--lake", type=t.dir_path, help="lake folder, as the other lake commands take it"
    )
    t.format_option(verify, "print the findings as JSON")
    t.progress_option(verify)
    verify.set_defaults(func=cmd_lake_verify)


def _add_upgrade(lake_sub: Any) -> None:
    upgrade = lake_sub.add_parser(
        "upgrade",
        help="migrate a per-run-folder lake (objsearch.lake/1, written by older versions) into "
        "the fleet lake: every healthy run is copied into one Delta Lake table (objsearch.lake/2) "
        "and its folder removed; a damaged run is named and left in place",
    )
    upgrade.add_argument(
        "--lake",
        default=_default_lake(),
        type=t.dir_path,
        help=f"the per-run-folder lake ($OBJSEARCH_LAKE or {DEFAULT_LAKE}); on a missing folder, "
        "an empty fleet lake is created",
    )
    upgrade.add_argument(
        "--to",
        choices=["fleet"],
        default="fleet",
        help="the format to migrate to: fleet (the only one; the default)",
    )
    upgrade.add_argument(
        "--into",
        metavar="LAKE",
        type=t.text,
        help="write the fleet table there (a folder or s3://bucket/prefix) and leave --lake as "
        "it is",
    )
    t.progress_option(upgrade)
    upgrade.set_defaults(func=cmd_lake_upgrade)


def _add_compact(lake_sub: Any) -> None:
    compact = lake_sub.add_parser(
        "compact",
        help="fleet lake: rewrite small (and unhashed) data files into few large "
        "content-addressed ones, checkpoint the log, delete files no recent version reads",
    )
    compact.add_argument(
        "--lake",
        default=_default_lake(),
        type=t.text,
        help=f"fleet lake folder or s3:// URI ($OBJSEARCH_LAKE or {DEFAULT_LAKE})",
    )
    compact.add_argument(
        "--keep-hours",
        type=t.float_range(0.0, 10_000.0),
        default=1.0,
        metavar="HOURS",
        help="keep replaced files this long for readers that started before (1)",
    )
    compact.set_defaults(func=cmd_lake_compact)


def register(sub: Any) -> None:
    _add_query(sub)
    lake = sub.add_parser("lake", help="put event logs into the analytics lake, list what it holds")
    lake_sub = lake.add_subparsers(dest="lake_command", required=True, metavar="SUBCOMMAND")
    _add_add(lake_sub)
    _add_ls(lake_sub)
    _add_verify(lake_sub)
    _add_upgrade(lake_sub)
    _add_compact(lake_sub)
