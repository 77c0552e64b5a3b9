"""The lake-damage battery: damage a real lake's files every way a disk or a careless hand can,
then ask it questions through the command line and hold it to "never answer wrong".

A lake of a few runs is built with the real CLI from the bundled data (``objsearch search``, then
``objsearch lake add``). Each variant is a copy of it with one kind of damage (:data:`KINDS`):
bit flips inside data pages, in the footer or anywhere, a burst of bytes, a cut, a zeroed
range, garbage appended, a file deleted, two runs' files swapped, one run's file copied over
another's, a table re-encoded as valid Parquet with one value changed, a table added, a manifest
flipped, cut or deleted, two run folders swapped. Then:

* ``objsearch query`` of every row of every view (each row hashed), and
* ``objsearch lake verify --format json``.

Each variant gets one verdict, the worst of:

* **clear error** — the damage was reported (exit 2 with ``objsearch: error:``, or exit 0 with a
  warning naming the damaged run) and the answer is exactly the intact lake's answer without
  the runs named;
* **unchanged** — nothing reported and the answer is the intact one (damage no reader sees: a
  deleted derived table is recomputed from the events);
* **traceback** — a Python traceback, or an exit status other than 0 and 2;
* **silent change** — the answer differs and nothing said so, or ``lake verify`` names fewer
  runs than the query left out;
* **loss** — the damage was reported but rows of runs not named are missing or changed, a
  healthy run was named, ``lake verify`` named more runs than the query left out, or a reader
  changed a file of the lake.

``benchmarks/lake_damage.py`` runs ≥ 200 variants and prints the counts;
``tests/test_lake_battery.py`` runs one of every kind, and the control without digests.
"""

from __future__ import annotations

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

from objsearch.cli_battery import BatteryOutcome, run_in_process
from objsearch.events.derived import derived_tables
from objsearch.events.lake import RUN_FILE
from objsearch.events.lake_digest import FILES_KEY, SELF_KEY
from objsearch.product import STORE
from objsearch.testing.killtest import tree

COLUMNS = ("clear error", "unchanged", "traceback", "silent change", "loss")
#: The runs of the battery's lake: (run name, target); every search starts in kitchen-1.
RUNS = (("apple", "Apple"), ("cup", "Cup"), ("bowl", "Bowl"))
_NAMED = re.compile(r"run=([A-Za-z0-9][A-Za-z0-9._-]*)")


def build_lake(root: Path) -> Path:
    """A lake of :data:`RUNS` made by the real CLI (one search each, then ``lake add``)."""
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


def run_cli(argv: Sequence[str]) -> BatteryOutcome:
    """:func:`objsearch.cli_battery.run_in_process` with the CLI's log lines (the warnings that
    name damaged runs) added to the captured stderr."""
    lines = io.StringIO()
    handler = logging.StreamHandler(lines)
    handler.setFormatter(logging.Formatter("objsearch: %(levelname)s: %(message)s"))
    handler.setLevel(logging.WARNING)
    root = logging.getLogger()
    root.addHandler(handler)
    try:
        outcome = run_in_process(argv)
    finally:
        root.removeHandler(handler)
    return BatteryOutcome(outcome.code, outcome.stdout, outcome.stderr + lines.getvalue())


def strip_digests(lake: Path) -> None:
    """Rewrite every manifest as code before file digests wrote it."""
    for manifest in lake.glob(f"robot=*/date=*/run=*/{RUN_FILE}"):
        doc = json.loads(manifest.read_bytes())
        for key in (FILES_KEY, SELF_KEY):
            doc.pop(key, None)
        manifest.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n", encoding="utf-8")


# -- the kinds of damage ------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Damage:
    """What a variant did: which runs it touched and how many files."""

    runs: frozenset[str]
    files: int
    #: the files changed, relative to the lake's table (the fleet battery's; the folder
    #: battery judges by runs)
    touched: frozenset[str] = frozenset()


Kind = Callable[[random.Random, Path], Damage]


def _run_dirs(lake: Path) -> list[Path]:
    return sorted(p for p in lake.glob("robot=*/date=*/run=*") if p.is_dir())


def _run_of(path: Path) -> str:
    return next(p.name.removeprefix("run=") for p in path.parents if p.name.startswith("run="))


def _tables(lake: Path) -> list[Path]:
    return sorted(lake.glob("robot=*/date=*/run=*/*.parquet")) + sorted(
        lake.glob("robot=*/date=*/run=*/_derived/*.parquet")
    )


def _footer_start(data: bytes | bytearray) -> int:
    return len(data) - 8 - int.from_bytes(data[-8:-4], "little")


def _edit(path: Path, change: Callable[[bytearray], bytes | bytearray]) -> Damage:
    path.write_bytes(bytes(change(bytearray(path.read_bytes()))))
    return Damage(frozenset({_run_of(path)}), 1)


def _flip(rng: random.Random, data: bytearray, lo: int, hi: int) -> bytearray:
    at = rng.randrange(lo, max(lo + 1, hi))
    data[at] ^= 1 << rng.randrange(8)
    return data


#: Damage to one file's bytes (the file given whole, returned changed); what the folder lake's
#: and the fleet lake's batteries (:mod:`objsearch.fleet_battery`) both do to a Parquet file.
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


def _edit_a_table(name: str) -> Kind:
    edit = EDITS[name]

    def kind(rng: random.Random, lake: Path) -> Damage:
        return _edit(rng.choice(_tables(lake)), lambda d: edit(rng, d))

    return kind


def delete_file(rng: random.Random, lake: Path) -> Damage:
    path = rng.choice(_tables(lake))
    path.unlink()
    return Damage(frozenset({_run_of(path)}), 1)


def _pair(rng: random.Random, lake: Path) -> tuple[Path, Path]:
    """The same table (by name in its run) in two different runs."""
    runs = _run_dirs(lake)
    while True:
        a, b = rng.sample(runs, 2)
        shared = sorted(
            p.relative_to(a)
            for p in _tables(lake)
            if p.is_relative_to(a) and (b / p.relative_to(a)).is_file()
        )
        if shared:
            name = rng.choice(shared)
            return a / name, b / name


def swap_between_runs(rng: random.Random, lake: Path) -> Damage:
    a, b = _pair(rng, lake)
    data_a, data_b = a.read_bytes(), b.read_bytes()
    a.write_bytes(data_b)
    b.write_bytes(data_a)
    return Damage(frozenset({_run_of(a), _run_of(b)}), 2)


def copy_from_other_run(rng: random.Random, lake: Path) -> Damage:
    a, b = _pair(rng, lake)
    a.write_bytes(b.read_bytes())
    return Damage(frozenset({_run_of(a)}), 1)


def rewrite_one_value(rng: random.Random, lake: Path) -> Damage:
    """Valid Parquet (page checksums and all) whose one numeric value differs by one."""
    path = one_value_changed(rng, _tables(lake))
    return Damage(frozenset({_run_of(path)}), 1)


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


def add_table(rng: random.Random, lake: Path) -> Damage:
    """A run gets an event table it did not commit: another run's table of a type it lacks if
    there is one, else a copy of one of its own under another name."""
    target = rng.choice(_run_dirs(lake))
    donors = [
        p for p in lake.glob("robot=*/date=*/run=*/*.parquet") if not (target / p.name).exists()
    ]
    if donors:
        donor = rng.choice(sorted(donors))
        shutil.copyfile(donor, target / donor.name)
    else:
        donor = rng.choice(sorted(target.glob("*.parquet")))
        shutil.copyfile(donor, target / f"copy-{donor.name}")
    return Damage(frozenset({_run_of(target / "x")}), 1)


def _manifest(rng: random.Random, lake: Path) -> Path:
    return rng.choice(_run_dirs(lake)) / RUN_FILE


def manifest_bit_flip(rng: random.Random, lake: Path) -> Damage:
    return _edit(_manifest(rng, lake), lambda d: _flip(rng, d, 0, len(d)))


def manifest_truncate(rng: random.Random, lake: Path) -> Damage:
    return _edit(_manifest(rng, lake), lambda d: d[: rng.randrange(0, len(d))])


def manifest_delete(rng: random.Random, lake: Path) -> Damage:
    path = _manifest(rng, lake)
    path.unlink()
    return Damage(frozenset({_run_of(path)}), 1)


def swap_run_folders(rng: random.Random, lake: Path) -> Damage:
    a, b = rng.sample(_run_dirs(lake), 2)
    tmp = a.with_name(a.name + ".swap")
    a.rename(tmp)
    b.rename(a)
    tmp.rename(b)
    return Damage(frozenset({_run_of(a / "x"), _run_of(b / "x")}), 2)


KINDS: dict[str, Kind] = {
    **{name: _edit_a_table(name) for name in EDITS},
    "file deleted": delete_file,
    "swapped between runs": swap_between_runs,
    "copied from another run": copy_from_other_run,
    "valid Parquet, one value changed": rewrite_one_value,
    "table added to a run": add_table,
    "manifest bit flip": manifest_bit_flip,
    "manifest truncated": manifest_truncate,
    "manifest deleted": manifest_delete,
    "run folders swapped": swap_run_folders,
}


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


def _named(stderr: str) -> set[str]:
    """The runs the warnings name as left out (the first ``run=`` of a line is its folder)."""
    return {
        m.group(1)
        for line in stderr.splitlines()
        if "damaged run" in line and (m := _NAMED.search(line)) is not None
    }


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
    """The verdict of one variant (:data:`COLUMNS`) and why."""
    crash = crashed(query, verify)
    if crash is not None:
        return crash
    if changed_by_reading:
        return "loss", "a reader changed a file of the lake"
    if verify.code == 2 and "objsearch: error: " not in verify.stderr:
        return "traceback", f"verify: exit 2 without a clear error: {verify.stderr[-300:]}"
    verified = {
        _run_of(Path(d["run"]) / "x") for d in json.loads(verify.stdout or "{}").get("damaged", [])
    }
    if query.code == 2:
        if "objsearch: error: " not in query.stderr:
            return "traceback", f"query: exit 2 without a clear error: {query.stderr[-300:]}"
        return "clear error", ""
    named = _named(query.stderr)
    answer = answer_rows(query)
    expected = [r for r in intact if r[1] not in named]
    if not named:
        if answer != intact:
            return "silent change", "the answer changed without a word"
        if verified:
            return "loss", f"verify named {sorted(verified)}, the query none"
        return "unchanged", ""
    if answer != expected:
        return "loss", f"runs {sorted(named)} named, yet the other runs' rows differ"
    if named - damage.runs:
        return "loss", f"healthy runs named damaged: {sorted(named - damage.runs)}"
    if verified != named:
        verdict = "silent change" if named - verified else "loss"
        return verdict, f"verify named {sorted(verified)}, the query {sorted(named)}"
    return "clear error", ""


def run_battery(
    lake: Path,
    work: Path,
    *,
    per_kind: int,
    seed: int,
    kinds: Sequence[str] | None = None,
    without_digests: bool = False,
) -> Report:
    """Try ``per_kind`` variants of every kind of damage on copies (under ``work``) of ``lake``
    (made by :func:`build_lake`; left as it is).

    ``without_digests`` takes the digests out of the copies' manifests first, as code before
    them wrote them: the control that shows the battery sees what digests catch."""
    intact_lake = work / "intact"
    shutil.rmtree(intact_lake, ignore_errors=True)
    shutil.copytree(lake, intact_lake)
    if without_digests:
        strip_digests(intact_lake)
    return try_variants(
        intact_lake,
        work,
        KINDS,
        kinds or list(KINDS),
        per_kind=per_kind,
        seed=seed,
        judge=lambda intact, damage, query, verify, changed, _variant: judge(
            intact, damage, query, verify, changed
        ),
    )


#: A verdict on one damaged lake: (intact rows, the damage, query, verify, whether reading
#: changed the lake, the damaged lake's folder) → (verdict, why).
Judge = Callable[
    [list[tuple[str, str, str]], Damage, BatteryOutcome, BatteryOutcome, bool, Path],
    tuple[str, str],
]


def try_variants(
    intact_lake: Path,
    work: Path,
    table: Mapping[str, Kind],
    names: Sequence[str],
    *,
    per_kind: int,
    seed: int,
    judge: Judge,
) -> Report:
    """The battery's one loop, for the folder lake and the fleet lake alike: ask the intact lake,
    then for each kind of ``names`` (from ``table``) damage ``per_kind`` copies of it (under
    ``work``), ask each copy ``objsearch query`` of every row and ``objsearch lake verify``, and
    count ``judge``'s verdicts."""
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
            verdict, why = judge(intact, damage, query, verify, tree(lake) != before, lake)
            report.tried += 1
            report.files += damage.files
            report.counts[verdict] += 1
            row[verdict] += 1
            row["tried"] += 1
            if verdict in ("traceback", "silent change", "loss"):
                report.flagged.append(f"{name} #{i}: {verdict}: {why}")
    return report
