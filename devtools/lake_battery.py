"""The lake-damage battery: damage a real fleet lake's files every way a disk or a careless hand
can, then ask it questions through the command line and hold it to "never answer wrong".

The lake (one Delta table, :class:`objsearch.events.lake.TableLake`) holds three runs made with the
real CLI from the bundled data (``objsearch search``, then one ``objsearch lake add`` a run, so a
data file holds one run's rows of one type, as a fleet's files are between compactions). Each
variant is a copy of it with one kind of damage (:data:`KINDS`): a data file's bytes (bit flips
inside data pages, in the footer or anywhere, a burst of bytes, a cut, a zeroed range, garbage
appended), a data file deleted or rewritten as valid Parquet with one value changed, or the
table's log (a commit file's bit flipped, cut or deleted). Then:

* ``objsearch query`` of every row of every view (each row hashed; its process forked from a
  warm one, :mod:`devtools.query_server`), and
* ``objsearch lake verify --format json``.

Each variant gets one verdict, the worst of:

* **clear error** — the query failed with ``objsearch: error:``, or it warned that it left out the
  damaged file, answered with the intact lake's rows less some (none changed, none added), and
  ``lake verify`` named the file too;
* **unchanged** — no warning and the intact answer (damage no reader sees);
* **traceback** — a traceback, or an exit status other than 0 and 2;
* **silent change** — the answer holds a row the intact lake does not, or lacks rows, and the
  query said nothing; or the query left a file out that ``lake verify`` did not name;
* **loss** — a healthy file was named damaged, or a reader changed a file of the lake.

The lake leaves out the damaged *file* — one type of one run here, of many runs once compacted —
so a clear error may answer with a run's other types still in (docs/analytics.md).
``benchmarks/lake_damage.py`` runs many variants and prints the counts;
``tests/test_lake_battery.py`` runs one of every kind.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import io
import json
import logging
import random
import re
import shutil
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from devtools.cli_battery import BatteryOutcome, run_in_process
from devtools.killtest import tree
from devtools.query_server import forked_queries
from objsearch.events.derived import derived_tables
from objsearch.product import STORE

COLUMNS = ("clear error", "unchanged", "traceback", "silent change", "loss")
#: The runs of the battery's lake: (run name, target); every search starts in kitchen-1.
RUNS = (("apple", "Apple"), ("cup", "Cup"), ("bowl", "Bowl"))
TABLE = "events"
#: what the query's warning says: "…: damaged data file left out of every view: <file> has …" (the
#: file relative to the table, then why).
_LEFT_OUT = re.compile(r"damaged data file left out of every view: (type=[^\s:]+)")


def build_lake(root: Path) -> Path:
    """A fleet lake of :data:`RUNS` made by the real CLI (one search each, then one ``lake add``
    a run)."""
    lake = root / "lake"
    for run, target in RUNS:
        log = root / f"log-{run}"
        for argv in (
            [
                "search",
                target,
                "--start",
                "kitchen-1",
                "--log",
                str(log),
                "--format",
                "json",
            ],
            ["lake", "add", str(log), "--robot", "r1", "--run", run, "--lake", str(lake)],
        ):
            outcome = run_cli(argv)
            if outcome.code != 0:
                raise RuntimeError(f"objsearch {' '.join(argv)}: {outcome.stderr}")
    return lake


def every_row_sql() -> str:
    """One query over every view, each row hashed: any changed value changes the answer."""
    views = [*STORE.registry.types, *(d.name for d in derived_tables(STORE))]
    parts = [
        f"SELECT '{v}' AS view, run, md5(CAST(x AS VARCHAR)) AS row FROM \"{v}\" x" for v in views
    ]
    return " UNION ALL ".join(parts) + " ORDER BY ALL"


@functools.cache
def _parser() -> argparse.ArgumentParser:
    """One command tree for every command of the batteries (building it took about 40 ms a
    command, 10 s of the lake-log battery's 246); each command names its lake, so no default
    read from the environment when it was built is used."""
    from objsearch.cli import build_parser

    return build_parser()


def run_cli(argv: Sequence[str], *, fork_queries: bool = True) -> BatteryOutcome:
    """:func:`devtools.cli_battery.run_in_process` with the CLI's log lines (the warnings that
    name damaged runs) added to the captured stderr. ``objsearch query``'s process is forked from
    a warm one (:func:`devtools.query_server.forked_queries`: its start-up was most of the
    batteries' time) unless ``fork_queries`` is false (a fresh interpreter, as shipped)."""
    lines = io.StringIO()
    handler = logging.StreamHandler(lines)
    handler.setFormatter(logging.Formatter("objsearch: %(levelname)s: %(message)s"))
    handler.setLevel(logging.WARNING)
    root = logging.getLogger()
    root.addHandler(handler)
    try:
        with forked_queries() if fork_queries else contextlib.nullcontext():
            outcome = run_in_process(argv, parser=_parser())
    finally:
        root.removeHandler(handler)
    return BatteryOutcome(outcome.code, outcome.stdout, outcome.stderr + lines.getvalue())


# -- the kinds of damage ------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Damage:
    """What a variant did: how many files it changed, and which."""

    files: int
    #: the files changed, relative to the lake's table
    touched: frozenset[str] = frozenset()


Kind = Callable[[random.Random, Path], Damage]


def _footer_start(data: bytes | bytearray) -> int:
    return len(data) - 8 - int.from_bytes(data[-8:-4], "little")


def _flip(rng: random.Random, data: bytearray, lo: int, hi: int) -> bytearray:
    at = rng.randrange(lo, max(lo + 1, hi))
    data[at] ^= 1 << rng.randrange(8)
    return data


#: Damage to one file's bytes (the file given whole, returned changed).
Edit = Callable[[random.Random, bytearray], bytes | bytearray]


def _burst(rng: random.Random, d: bytearray) -> bytearray:
    at = rng.randrange(4, len(d) - 8)
    for i in range(at, min(at + rng.randint(2, 16), len(d) - 8)):
        d[i] = rng.randrange(256)
    return d


def _zero(rng: random.Random, d: bytearray) -> bytearray:
    size = rng.choice([64, 512, 4096])
    at = rng.randrange(0, max(1, len(d) - size))
    d[at : at + size] = bytes(len(d[at : at + size]))
    return d


EDITS: dict[str, Edit] = {
    "bit flip in a data page": lambda rng, d: _flip(rng, d, 4, _footer_start(d)),
    "bit flip in the footer": lambda rng, d: _flip(rng, d, _footer_start(d), len(d) - 8),
    "bit flip anywhere": lambda rng, d: _flip(rng, d, 0, len(d)),
    "random bytes (2-16)": _burst,
    "truncated": lambda rng, d: d[: rng.randrange(0, len(d))],
    "zeroed range": _zero,
    "garbage appended": lambda rng, d: d + rng.randbytes(rng.randint(1, 64)),
}


def one_value_changed(rng: random.Random, files: Sequence[Path]) -> Path:
    """Rewrite one of ``files`` that has a top-level numeric column as valid Parquet (page
    checksums and all) with one value of it one more; returns the file."""
    while True:
        path = rng.choice(files)
        table = pq.ParquetFile(path).read()
        numeric = [
            i
            for i, f in enumerate(table.schema)
            if (pa.types.is_integer(f.type) or pa.types.is_floating(f.type))
            and table.num_rows
            and table.column(i).null_count < table.num_rows
        ]
        if numeric:
            break
    i = rng.choice(numeric)
    column = table.column(i).combine_chunks()
    row = rng.choice([r for r in range(table.num_rows) if column[r].is_valid])
    values = column.to_pylist()
    values[row] = values[row] + 1
    table = table.set_column(i, table.schema.field(i), pa.array(values, column.type))
    assert not pc.all(pc.equal(table.column(i), column)).as_py()
    pq.write_table(table, path, compression="zstd", write_page_checksum=True)
    return path


def _data_files(lake: Path) -> list[Path]:
    return sorted((lake / TABLE).glob("type=*/*.parquet"))


def _commits(lake: Path) -> list[Path]:
    return sorted((lake / TABLE / "_delta_log").glob("*.json"))


def _touched(lake: Path, *paths: Path) -> Damage:
    return Damage(len(paths), frozenset(str(p.relative_to(lake / TABLE)) for p in paths))


def _edit_a_data_file(name: str) -> Kind:
    edit = EDITS[name]

    def kind(rng: random.Random, lake: Path) -> Damage:
        path = rng.choice(_data_files(lake))
        path.write_bytes(bytes(edit(rng, bytearray(path.read_bytes()))))
        return _touched(lake, path)

    return kind


def _delete_data_file(rng: random.Random, lake: Path) -> Damage:
    path = rng.choice(_data_files(lake))
    path.unlink()
    return _touched(lake, path)


def _one_value_changed(rng: random.Random, lake: Path) -> Damage:
    return _touched(lake, one_value_changed(rng, _data_files(lake)))


def _commit_bit_flip(rng: random.Random, lake: Path) -> Damage:
    path = rng.choice(_commits(lake))
    data = bytearray(path.read_bytes())
    data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
    path.write_bytes(bytes(data))
    return _touched(lake, path)


def _commit_truncated(rng: random.Random, lake: Path) -> Damage:
    path = rng.choice(_commits(lake))
    data = path.read_bytes()
    path.write_bytes(data[: rng.randrange(0, len(data))])
    return _touched(lake, path)


def _commit_deleted(rng: random.Random, lake: Path) -> Damage:
    path = rng.choice(_commits(lake))
    path.unlink()
    return _touched(lake, path)


KINDS: dict[str, Kind] = {
    **{name: _edit_a_data_file(name) for name in EDITS},
    "file deleted": _delete_data_file,
    "valid Parquet, one value changed": _one_value_changed,
    "commit file bit flip": _commit_bit_flip,
    "commit file truncated": _commit_truncated,
    "commit file deleted": _commit_deleted,
}


def _named(stderr: str) -> set[str]:
    """The data files the query's warnings say it left out, relative to the table."""
    return {m.group(1) for m in _LEFT_OUT.finditer(stderr)}


# -- judging ----------------------------------------------------------------------------------


@dataclass
class Report:
    tried: int = 0
    files: int = 0
    counts: Counter[str] = field(default_factory=Counter)
    by_kind: dict[str, Counter[str]] = field(default_factory=dict)
    flagged: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not any(self.counts[c] for c in ("traceback", "silent change", "loss"))


def answer_rows(outcome: BatteryOutcome) -> list[tuple[str, str, str]]:
    """The rows of an :func:`every_row_sql` answer printed as JSON: (view, run, row hash)."""
    return [(r["view"], r["run"], r["row"]) for r in json.loads(outcome.stdout)]


def crashed(query: BatteryOutcome, verify: BatteryOutcome) -> tuple[str, str] | None:
    """The ``traceback`` verdict if either command printed one or exited other than 0 or 2."""
    for what, outcome in (("query", query), ("verify", verify)):
        if "Traceback (most recent call last)" in outcome.stderr or outcome.code not in (0, 2):
            return "traceback", f"{what}: exit {outcome.code}: {outcome.stderr[-600:]}"
    return None


def judge(
    intact: list[tuple[str, str, str]],
    damage: Damage,
    query: BatteryOutcome,
    verify: BatteryOutcome,
    changed_by_reading: bool,
) -> tuple[str, str]:
    """The verdict of one variant (:data:`COLUMNS`) and why (see the module's docstring)."""
    crash = crashed(query, verify)
    if crash is not None:
        return crash
    for what, outcome in (("query", query), ("verify", verify)):
        if outcome.code == 2 and "objsearch: error: " not in outcome.stderr:
            return "traceback", f"{what}: exit 2 without a clear error: {outcome.stderr[-300:]}"
    if changed_by_reading:
        return "loss", "a reader changed a file of the lake"
    if verify.code == 2 and not verify.stdout.strip():  # verify refused the lake outright
        verified = set(damage.touched)
    else:
        verified = {d["file"] for d in json.loads(verify.stdout or "{}").get("damaged", [])}
    if query.code == 2:
        return "clear error", ""
    named = _named(query.stderr)
    answer = answer_rows(query)
    if not named:
        if answer != intact:
            return "silent change", "the answer changed without a word"
        return "unchanged", ""
    if named - damage.touched:
        return "loss", f"healthy files named damaged: {sorted(named - damage.touched)}"
    if Counter(answer) - Counter(intact):
        return "silent change", f"left out {sorted(named)}, yet answered rows the lake never held"
    if not named <= verified:
        return (
            "silent change",
            f"the query left out {sorted(named)}, verify named {sorted(verified)}",
        )
    return "clear error", ""


def run_battery(
    lake: Path,
    work: Path,
    *,
    per_kind: int,
    seed: int,
    kinds: list[str] | None = None,
) -> Report:
    """Try ``per_kind`` variants of every kind of :data:`KINDS` on copies (under ``work``)
    of ``lake`` (made by :func:`build_lake`; left as it is)."""
    intact_lake = work / "intact"
    shutil.rmtree(intact_lake, ignore_errors=True)
    shutil.copytree(lake, intact_lake)
    return try_variants(
        intact_lake,
        work,
        KINDS,
        kinds or list(KINDS),
        per_kind=per_kind,
        seed=seed,
    )


def try_variants(
    intact_lake: Path,
    work: Path,
    table: Mapping[str, Kind],
    names: Sequence[str],
    *,
    per_kind: int,
    seed: int,
) -> Report:
    """The battery's loop: ask the intact lake, then for each kind of ``names`` (from ``table``)
    damage ``per_kind`` copies of it (under ``work``), ask each copy ``objsearch query`` of
    every row and ``objsearch lake verify``, and count :func:`judge`'s verdicts."""
    sql = every_row_sql()
    baseline = run_cli(["query", "--lake", str(intact_lake), "--format", "json", sql])
    if baseline.code != 0 or run_cli(["lake", "verify", str(intact_lake)]).code != 0:
        raise RuntimeError(f"the intact lake does not answer cleanly: {baseline.stderr}")
    intact = answer_rows(baseline)
    report = Report()
    rng = random.Random(seed)
    for name in names:
        row = report.by_kind.setdefault(name, Counter())
        for i in range(per_kind):
            lake = work / "variant" / "lake"
            shutil.rmtree(lake.parent, ignore_errors=True)
            shutil.copytree(intact_lake, lake)
            damage = table[name](rng, lake)
            before = tree(lake)
            query = run_cli(["query", "--lake", str(lake), "--format", "json", sql])
            verify = run_cli(["lake", "verify", str(lake), "--format", "json"])
            verdict, why = judge(intact, damage, query, verify, tree(lake) != before)
            report.tried += 1
            report.files += damage.files
            report.counts[verdict] += 1
            row[verdict] += 1
            row["tried"] += 1
            if verdict in ("traceback", "silent change", "loss"):
                report.flagged.append(f"{name} #{i}: {verdict}: {why}")
    return report
