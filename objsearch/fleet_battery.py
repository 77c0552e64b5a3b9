"""The lake-damage battery on the fleet lake (one Delta table, :mod:`objsearch.events.lake_table`):
the folder lake's battery (:mod:`objsearch.lake_battery`) asks whether a lake ever answers wrong
without a word; this asks the same of the fleet lake, whose checks are others.

The lake holds the battery's three runs, each committed by its own ``objsearch lake add`` (so a
data file holds one run's rows of one type, as a fleet's files are between compactions). Each
variant damages one thing: a data file's bytes as the folder battery does (:data:`EDITS`), a data
file deleted or rewritten as valid Parquet with one value changed, or the table's log (a commit
file's bit flipped, cut or deleted). Then ``objsearch query`` of every row of every view and
``objsearch lake verify --format json``, and one verdict, the worst of:

* **clear error** — the query failed with ``objsearch: error:``, or it warned that it left out the
  damaged file, answered with the intact lake's rows less some (none changed, none added), and
  ``lake verify`` named the file too;
* **unchanged** — no warning and the intact answer (damage no reader sees);
* **traceback** — a traceback, or an exit status other than 0 and 2;
* **silent change** — the answer holds a row the intact lake does not, or lacks rows, and the
  query said nothing; or the query left a file out that ``lake verify`` did not name;
* **loss** — a healthy file was named damaged, or a reader changed a file of the lake.

What it does not judge (a difference from the folder lake, documented in docs/analytics.md): the
folder lake leaves a damaged *run* out of every view; the fleet lake leaves out the damaged
*file* — one type of one run here, of many runs once compacted — so a clear error here may answer
with a run's other types still in.
"""

from __future__ import annotations

import json
import random
import re
import shutil
from collections import Counter
from collections.abc import Callable
from pathlib import Path

from objsearch.cli_battery import BatteryOutcome
from objsearch.lake_battery import (
    EDITS,
    RUNS,
    Damage,
    Report,
    answer_rows,
    build_lake,
    crashed,
    one_value_changed,
    run_cli,
    try_variants,
)

TABLE = "events"
#: what the query's warning says: "…: damaged data file left out of every view: <file> has …" (the
#: file relative to the table, then why).
_LEFT_OUT = re.compile(r"damaged data file left out of every view: (type=[^\s:]+)")


def build_fleet_lake(root: Path) -> Path:
    """A fleet lake of :data:`~objsearch.lake_battery.RUNS`, one ``lake add`` a run (their logs
    made by :func:`~objsearch.lake_battery.build_lake`)."""
    build_lake(root)
    fleet = root / "fleet"
    steps = [["lake", "upgrade", "--to", "fleet", "--lake", str(fleet)]]
    steps += [
        [
            "lake",
            "add",
            str(root / f"log-{run}"),
            "--robot",
            "r1",
            "--run",
            run,
            "--lake",
            str(fleet),
        ]
        for run, _ in RUNS
    ]
    for argv in steps:
        outcome = run_cli(argv)
        if outcome.code != 0:
            raise RuntimeError(f"objsearch {' '.join(argv)}: {outcome.stderr}")
    return fleet


FleetKind = Callable[[random.Random, Path], Damage]


def _data_files(lake: Path) -> list[Path]:
    return sorted((lake / TABLE).glob("type=*/*.parquet"))


def _commits(lake: Path) -> list[Path]:
    return sorted((lake / TABLE / "_delta_log").glob("*.json"))


def _touched(lake: Path, *paths: Path) -> Damage:
    return Damage(
        frozenset(), len(paths), frozenset(str(p.relative_to(lake / TABLE)) for p in paths)
    )


def _edit_a_data_file(name: str) -> FleetKind:
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


FLEET_KINDS: dict[str, FleetKind] = {
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


def judge(
    intact: list[tuple[str, str, str]],
    damage: Damage,
    query: BatteryOutcome,
    verify: BatteryOutcome,
    changed_by_reading: bool,
    lake: Path,
) -> tuple[str, str]:
    """The verdict of one variant and why (see the module's docstring). ``lake``: the damaged
    copy (unused: the warnings name files relative to the table)."""
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


def run_fleet_battery(
    lake: Path,
    work: Path,
    *,
    per_kind: int,
    seed: int,
    kinds: list[str] | None = None,
) -> Report:
    """Try ``per_kind`` variants of every kind of :data:`FLEET_KINDS` on copies (under ``work``)
    of the fleet ``lake`` (made by :func:`build_fleet_lake`; left as it is)."""
    intact_lake = work / "intact"
    shutil.rmtree(intact_lake, ignore_errors=True)
    shutil.copytree(lake, intact_lake)
    return try_variants(
        intact_lake,
        work,
        FLEET_KINDS,
        kinds or list(FLEET_KINDS),
        per_kind=per_kind,
        seed=seed,
        judge=judge,
    )
