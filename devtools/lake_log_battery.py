"""The lake-bookkeeping battery: edit a real fleet lake's transaction log and its runs' records
(``_run`` files) every way a careless hand or a broken sync can, then ask it everything through
the command line and hold it to "never answer wrong, never make a loss permanent".

The lake is :func:`devtools.lake_battery.build_lake`'s (three runs, one ``objsearch lake add``
each, so one commit file a run), and a compacted copy of it (``objsearch lake compact``: its
newest commit is the compaction's, read from a checkpoint). Each variant is a copy of one of them
with one edit (:data:`KINDS`): an ``add``, ``txn`` or ``commitInfo`` line of a commit removed, an
``add`` line duplicated, a commit file deleted, duplicated as the next version, cut at a line or
inside one, a bit flipped; the newest commit file deleted; a ``_run`` file deleted, cut, flipped
or replaced; the lake's record of its latest version (:data:`~objsearch.events.lake.head.HEAD_FILE`)
deleted or garbled. Each copy is asked, through the real CLI in-process (the query's process
forked from a warm one, :mod:`devtools.query_server`, as :func:`devtools.lake_battery.run_cli`
runs every command):

* ``objsearch query`` of every row of every view, ``objsearch lake ls --format json`` and
  ``objsearch lake verify --format json`` (none of them may change a file of the lake);
* ``objsearch lake compact --keep-hours 0`` on a copy, then the query again (a compaction must
  not make a loss permanent: its vacuum deletes the files no version names);
* ``objsearch lake add`` of a fourth run's log on another copy, then the query again.

Each variant gets the worst verdict of:

* **clear error** — a command refused with ``objsearch: error:`` or warned, and nothing below;
* **unchanged** — every command succeeded without a warning and answered as the intact lake;
* **traceback** — a traceback, an exit status other than 0 and 2, or exit 2 without
  ``objsearch: error:``;
* **silent change** — a command succeeded without a word and answered otherwise than the intact
  lake (query rows, ``lake ls`` runs), or ``lake verify`` passed a lake whose query or listing
  is not the intact one's, or a query after ``lake add`` lacks rows of the intact lake without
  a word;
* **loss** — a reader changed a file of the lake, or ``lake compact`` succeeded and the query
  afterwards answers without a word but otherwise than the intact lake (the loss made
  permanent).

``benchmarks/lake_log_damage.py`` runs every variant of every kind (each line of each commit,
each commit, each ``_run`` file) and prints the counts; ``tests/test_lake_log_battery.py`` runs
one of each kind.
"""

from __future__ import annotations

import json
import random
import re
import shutil
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from devtools.cli_battery import BatteryOutcome
from devtools.killtest import tree
from devtools.lake_battery import COLUMNS, answer_rows, build_lake, every_row_sql, run_cli
from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake
from objsearch.events.lake.head import HEAD_FILE
from objsearch.events.lake.schema import RUN_TYPE, TABLE_DIR

#: The run ``lake add`` adds to each damaged copy: (run name, target).
ADDED = ("phone", "Phone")
_WARNED = re.compile(r"objsearch: (warning|WARNING): ")
#: A variant: (kind, index); the index picks which line, commit or file (modulo how many).
Kind = Callable[[Path, int, random.Random], str]


# -- the edits ---------------------------------------------------------------------------------


def _log_dir(lake: Path) -> Path:
    return lake / TABLE_DIR / "_delta_log"


def _commits(lake: Path) -> list[Path]:
    return sorted(_log_dir(lake).glob("[0-9]*[0-9].json"))


def _lines(lake: Path, action: str) -> list[tuple[Path, int]]:
    """Every (commit file, line number) whose line is an ``action`` (add, txn, commitInfo …)."""
    found = []
    for path in _commits(lake):
        for i, line in enumerate(path.read_text(encoding="utf-8").splitlines()):
            if line.startswith(f'{{"{action}":'):
                found.append((path, i))
    return found


def _edit_lines(path: Path, edit: Callable[[list[str]], list[str]]) -> None:
    lines = path.read_text(encoding="utf-8").splitlines()
    path.write_text("".join(f"{line}\n" for line in edit(lines)), encoding="utf-8")


def _line_removed(action: str) -> Kind:
    def kind(lake: Path, i: int, rng: random.Random) -> str:
        path, at = (found := _lines(lake, action))[i % len(found)]
        _edit_lines(path, lambda lines: lines[:at] + lines[at + 1 :])
        return f"{path.name} line {at + 1}"

    return kind


def _add_duplicated(lake: Path, i: int, rng: random.Random) -> str:
    path, at = (found := _lines(lake, "add"))[i % len(found)]
    _edit_lines(path, lambda lines: lines[: at + 1] + lines[at:])
    return f"{path.name} line {at + 1}"


def _commit_deleted(lake: Path, i: int, rng: random.Random) -> str:
    path = (found := _commits(lake))[i % len(found)]
    path.unlink()
    return path.name


def _newest_deleted(lake: Path, i: int, rng: random.Random) -> str:
    path = _commits(lake)[-1]
    path.unlink()
    return path.name


def _commit_duplicated(lake: Path, i: int, rng: random.Random) -> str:
    commits = _commits(lake)
    path = commits[i % len(commits)]
    after = _log_dir(lake) / f"{int(commits[-1].stem) + 1:020d}.json"
    shutil.copyfile(path, after)
    return f"{path.name} as {after.name}"


def _cut_at_line(lake: Path, i: int, rng: random.Random) -> str:
    path = (found := _commits(lake))[i % len(found)]
    keep = rng.randrange(len(path.read_text(encoding="utf-8").splitlines()))
    _edit_lines(path, lambda lines: lines[:keep])
    return f"{path.name} after {keep} line(s)"


def _cut_in_line(lake: Path, i: int, rng: random.Random) -> str:
    path = (found := _commits(lake))[i % len(found)]
    data = path.read_bytes()
    path.write_bytes(data[: rng.randrange(1, len(data) - 1)])
    return path.name


def _commit_bit_flip(lake: Path, i: int, rng: random.Random) -> str:
    path = (found := _commits(lake))[i % len(found)]
    data = bytearray(path.read_bytes())
    data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
    path.write_bytes(bytes(data))
    return path.name


def _run_files(lake: Path) -> list[Path]:
    """The ``_run`` files of the table's current version (a compacted lake keeps the older
    ones on disk until a vacuum)."""
    files = TableLake(lake, store=STORE).data_files()
    return sorted(lake / TABLE_DIR / f.path for f in files if f.kind == RUN_TYPE)


def _run_file(edit: Callable[[bytes, random.Random], bytes | None]) -> Kind:
    def kind(lake: Path, i: int, rng: random.Random) -> str:
        path = (files := _run_files(lake))[i % len(files)]
        new = edit(path.read_bytes(), rng)
        if new is None:
            path.unlink()
        else:
            path.write_bytes(new)
        return str(path.relative_to(lake / TABLE_DIR))

    return kind


def _flip(data: bytes, rng: random.Random) -> bytes:
    out = bytearray(data)
    out[rng.randrange(len(out))] ^= 1 << rng.randrange(8)
    return bytes(out)


def _head_deleted(lake: Path, i: int, rng: random.Random) -> str:
    (lake / TABLE_DIR / HEAD_FILE).unlink()
    return HEAD_FILE


def _head_garbled(lake: Path, i: int, rng: random.Random) -> str:
    head = lake / TABLE_DIR / HEAD_FILE
    head.write_bytes(_flip(head.read_bytes(), rng))
    return HEAD_FILE


KINDS: dict[str, Kind] = {
    "add line removed": _line_removed("add"),
    "add line duplicated": _add_duplicated,
    "txn line removed": _line_removed("txn"),
    "commitInfo line removed": _line_removed("commitInfo"),
    "commit file deleted": _commit_deleted,
    "newest commit file deleted": _newest_deleted,
    "commit duplicated as the next version": _commit_duplicated,
    "commit cut at a line": _cut_at_line,
    "commit cut inside a line": _cut_in_line,
    "commit bit flip": _commit_bit_flip,
    "_run file deleted": _run_file(lambda data, rng: None),
    "_run file cut": _run_file(lambda data, rng: data[: rng.randrange(len(data))]),
    "_run file bit flip": _run_file(_flip),
    "_run file garbage": _run_file(lambda data, rng: b"garbage"),
    "head record deleted": _head_deleted,
    "head record garbled": _head_garbled,
}


def variants(lake: Path, kind: str) -> int:
    """How many distinct targets a kind has on ``lake`` (lines, commits or files)."""
    if kind.endswith("line removed") or kind == "add line duplicated":
        return len(_lines(lake, kind.split()[0]))
    if kind.startswith("_run file"):
        return len(_run_files(lake))
    if kind.startswith("commit") and kind != "commitInfo line removed":
        return len(_commits(lake))
    return 1


# -- judging -----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Intact:
    """What the intact lake answers."""

    rows: list[tuple[str, str, str]]
    runs: list[dict[str, object]]


def _runs(outcome: BatteryOutcome) -> list[dict[str, object]]:
    return list(json.loads(outcome.stdout)) if outcome.stdout.strip() else []


def ask(lake: Path) -> tuple[BatteryOutcome, BatteryOutcome, BatteryOutcome]:
    """``query`` of every row, ``lake ls`` and ``lake verify`` of ``lake``."""
    query = run_cli(["query", "--lake", str(lake), "--format", "json", every_row_sql()])
    ls = run_cli(["lake", "ls", "--lake", str(lake), "--format", "json"])
    verify = run_cli(["lake", "verify", str(lake), "--format", "json", "--no-progress"])
    return query, ls, verify


def _said(outcome: BatteryOutcome) -> bool:
    """Whether a command refused or warned."""
    return outcome.code != 0 or bool(_WARNED.search(outcome.stderr))


def _crash(named: Sequence[tuple[str, BatteryOutcome]]) -> str | None:
    for what, outcome in named:
        if "Traceback (most recent call last)" in outcome.stderr or outcome.code not in (0, 2):
            return f"{what}: exit {outcome.code}: {outcome.stderr[-600:]}"
        if outcome.code == 2 and "objsearch: error: " not in outcome.stderr:
            return f"{what}: exit 2 without a clear error: {outcome.stderr[-300:]}"
    return None


def judge(
    intact: Intact,
    commands: dict[str, BatteryOutcome],
    changed_by_reading: bool,
) -> tuple[str, str]:
    """The verdict of one variant (:data:`~devtools.lake_battery.COLUMNS`) and why; see the
    module's docstring. ``commands``: query, ls, verify, compact, compacted query, add, added
    query."""
    crash = _crash(list(commands.items()))
    if crash is not None:
        return "traceback", crash
    if changed_by_reading:
        return "loss", "a reader changed a file of the lake"
    query, ls, verify = commands["query"], commands["ls"], commands["verify"]
    compacted, added = commands["compacted query"], commands["added query"]
    wrong_query = query.code == 0 and answer_rows(query) != intact.rows
    wrong_ls = ls.code == 0 and _runs(ls) != intact.runs
    compact_ok = commands["compact"].code == 0 and not _said(compacted)
    if compact_ok and answer_rows(compacted) != intact.rows:
        return "loss", "lake compact succeeded and the lake then answers otherwise, unsaid"
    if wrong_query and not _said(query):
        return "silent change", "the query answered otherwise without a word"
    if wrong_ls and not _said(ls):
        return "silent change", "lake ls listed other runs without a word"
    if verify.code == 0 and (wrong_query or wrong_ls or query.code or ls.code):
        return "silent change", "lake verify passed a lake that does not answer as it did"
    add_ok = commands["add"].code == 0 and not _said(added) and not _said(commands["add"])
    if add_ok and Counter(intact.rows) - Counter(answer_rows(added)):
        return "silent change", "after lake add the query lacks rows, unsaid"
    if any(_said(c) for c in commands.values()):
        return "clear error", ""
    return "unchanged", ""


# -- the loop ----------------------------------------------------------------------------------


@dataclass
class Report:
    tried: int = 0
    counts: Counter[str] = field(default_factory=Counter)
    by_kind: dict[str, Counter[str]] = field(default_factory=dict)
    flagged: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not any(self.counts[c] for c in ("traceback", "silent change", "loss"))


def build(root: Path) -> tuple[dict[str, Path], Path]:
    """The battery's two lakes, ``lake`` and ``compacted`` (by name), and the log ``lake add``
    adds to each variant."""
    lake = build_lake(root)
    compacted = root / "compacted"
    shutil.copytree(lake, compacted)
    log = root / f"log-{ADDED[0]}"
    for argv in (
        ["lake", "compact", "--lake", str(compacted)],
        ["search", ADDED[1], "--start", "kitchen-1", "--log", str(log), "--format", "json"],
    ):
        outcome = run_cli(argv)
        if outcome.code != 0:
            raise RuntimeError(f"objsearch {' '.join(argv)}: {outcome.stderr}")
    return {"lake": lake, "compacted": compacted}, log


def run_battery(
    lakes: dict[str, Path],
    log: Path,
    work: Path,
    *,
    per_kind: int | None,
    seed: int,
    kinds: Sequence[str] | None = None,
) -> Report:
    """Try every kind of :data:`KINDS` (or ``kinds``) on copies (under ``work``) of each of
    ``lakes`` (:func:`build`; left as they are): ``per_kind`` variants of each, or with None
    every target the kind has (each line, commit or file, :func:`variants`)."""
    report = Report()
    rng = random.Random(seed)
    for base, source in lakes.items():
        intact_lake = work / f"intact-{base}"
        shutil.rmtree(intact_lake, ignore_errors=True)
        shutil.copytree(source, intact_lake)
        query, ls, verify = ask(intact_lake)
        if query.code or ls.code or verify.code:
            said = query.stderr + ls.stderr + verify.stderr
            raise RuntimeError(f"the intact lake does not answer cleanly: {said[-2000:]}")
        intact = Intact(answer_rows(query), _runs(ls))
        # the intact lake compacts (its vacuum too) and takes a run, then answers: a check
        # that refused a healthy lake would pass as a clear error below
        healthy = _compacted_and_added(intact_lake, log, work / "healthy")
        if any(c.code for c in healthy.values()):
            raise RuntimeError(f"the intact lake refuses: {healthy}")
        if answer_rows(healthy["compacted query"]) != intact.rows:
            raise RuntimeError("the intact lake answers otherwise once compacted")
        for name in kinds or list(KINDS):
            row = report.by_kind.setdefault(name, Counter())
            targets = variants(intact_lake, name)
            # every target in turn, or ``per_kind`` picked at random
            picks = range(targets) if per_kind is None else [rng.randrange(targets)] * per_kind
            for n, i in enumerate(picks):
                verdict, why, what = _one(intact_lake, intact, log, work, name, i + n, rng)
                report.tried += 1
                report.counts[verdict] += 1
                row[verdict] += 1
                row["tried"] += 1
                if verdict in ("traceback", "silent change", "loss"):
                    report.flagged.append(f"{base}: {name} ({what}): {verdict}: {why}")
    return report


def _one(
    intact_lake: Path,
    intact: Intact,
    log: Path,
    work: Path,
    name: str,
    i: int,
    rng: random.Random,
) -> tuple[str, str, str]:
    """One variant: damage a copy, ask it, compact a copy and add to another, judge."""
    lake = work / "variant" / "lake"
    shutil.rmtree(lake.parent, ignore_errors=True)
    shutil.copytree(intact_lake, lake)
    what = KINDS[name](lake, i, rng)
    before = tree(lake)
    query, ls, verify = ask(lake)
    changed = tree(lake) != before
    commands = {"query": query, "ls": ls, "verify": verify}
    commands |= _compacted_and_added(lake, log, work / "variant")
    verdict, why = judge(intact, commands, changed)
    return verdict, why, what


def _compacted_and_added(lake: Path, log: Path, work: Path) -> dict[str, BatteryOutcome]:
    """``lake compact --keep-hours 0`` on a copy of ``lake`` then the query, and ``lake add``
    of ``log`` on another copy then the query (copies under ``work``)."""
    commands = {}
    sql = every_row_sql()
    for step, argv in (
        ("compact", ["lake", "compact", "--keep-hours", "0"]),
        ("add", ["lake", "add", str(log), "--robot", "r1", "--run", ADDED[0], "--no-progress"]),
    ):
        copy = work / step
        shutil.rmtree(copy, ignore_errors=True)
        shutil.copytree(lake, copy)
        commands[step] = run_cli([*argv, "--lake", str(copy)])
        after = run_cli(["query", "--lake", str(copy), "--format", "json", sql])
        commands["compacted query" if step == "compact" else "added query"] = after
    return commands


__all__ = ["COLUMNS", "KINDS", "Report", "build", "judge", "run_battery", "variants"]
