"""Issue 45's new-map measure from ``bench homes --new-map-day N`` outputs, as ``bench belief``
prints it: the first search of day N (the robot's first in the new map) of each run, the
strategy's path ÷ the memory-less ``ecost``'s on the same run (home, schedule); the ratio of sums
with a 95 % bootstrap CI over homes (both sums over the same draw, 10,000 resamples, seed 0), per
family and pooled, the mean paths, and the runs where the strategy's path is no longer than
ecost's. The target, "the first search after a new map no worse than the memory-less ecost", is
read as shown when the pooled CI's upper end is ≤ 1 (docs/results-perception.md).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

from objsearch.experiments.report_protocol import RESAMPLES, family, ratio_over_homes
from objsearch.experiments.runner import Row, inspection_suffix

#: The memory-less strategy the first search in a new map is held against.
MEMORYLESS = "ecost"
#: Strategies left out of the comparison: the references see where the object is.
REFERENCES = ("dist-oracle", "dist-oracle-global")

Run = tuple[str, str]


def new_map_day(folder: Path) -> int | None:
    """The day (scene) a ``bench homes`` output's robot moved into a new map (its summary.json's
    ``new_map_day``); None: never, or no summary.json."""
    path = folder / "summary.json"
    summary = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    day = summary.get("new_map_day")
    return None if day is None else int(day)


def new_map_frame(folder: Path) -> str:
    """Whether a ``bench homes`` output's new map kept the old frame (``same``: its
    summary.json names none) or had one of its own (``moved``)."""
    path = folder / "summary.json"
    summary = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    return str(summary.get("new_map_frame") or "same")


def first_in_new_map(rows: Sequence[Row], day: int) -> dict[str, dict[Run, Row]]:
    """Per strategy, per run (home, schedule): its first search of ``day`` (lowest task id)."""
    out: dict[str, dict[Run, Row]] = {}
    for r in rows:
        if r.scene != day:
            continue
        mine = out.setdefault(r.strategy, {})
        run = (r.home, r.placements)
        if run not in mine or r.task_id < mine[run].task_id:
            mine[run] = r
    return out


def _mean(values: Sequence[float]) -> float:
    return math.fsum(values) / len(values)


def new_map_lines(rows: Sequence[Row], day: int) -> list[str]:
    """The measure's table: each strategy but ecost and the references against ecost of its
    inspection (``a+cover`` against ``ecost+cover``), per family and pooled; the pooled row
    judged by the target. A run one of the two lacks is left out of both (and counted)."""
    firsts = first_in_new_map(rows, day)
    lines = [
        f"### First search after a new map (day {day})",
        "",
        f"The first search of day {day}, the first in the new map, of each run (home, schedule; "
        f"lowest task id), ÷ the memory-less {MEMORYLESS}'s on the same run; ratio of sums, 95 % "
        f"bootstrap CI over homes ({RESAMPLES:,} resamples, seed 0). Target: no worse than "
        f"{MEMORYLESS}, shown when the pooled CI's upper end is ≤ 1 (met), else not shown.",
        "",
    ]
    if not firsts:
        return [*lines, f"No search on day {day} in these runs."]
    lines += [
        f"| strategy | family | homes | runs | mean path, m | {MEMORYLESS}'s mean path, m "
        f"| ÷ {MEMORYLESS} | runs no longer than {MEMORYLESS}'s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    unpaired: list[str] = []
    compared = 0
    for s, mine in firsts.items():
        suffix = inspection_suffix(s)
        name = s.removesuffix(suffix)
        theirs = firsts.get(MEMORYLESS + suffix)
        if name == MEMORYLESS or name in REFERENCES or theirs is None:
            continue
        compared += 1
        runs = sorted(k for k in mine if k in theirs)
        lone = sorted(set(mine) ^ set(theirs))
        if lone:
            named = ", ".join(f"{home} {placements}" for home, placements in lone)
            unpaired.append(f"{s} ÷ {MEMORYLESS + suffix}: {named}")
        families = sorted({family(home) for home, _ in runs})
        for fam in [*families, "pooled"]:
            keep = [k for k in runs if fam == "pooled" or family(k[0]) == fam]
            if not keep:
                continue
            value, low, high, homes = ratio_over_homes(
                [(k[0], mine[k].path_length, theirs[k].path_length) for k in keep]
            )
            verdict = ""
            if fam == "pooled":
                verdict = " (met)" if high <= 1.0 else " (**not shown**)"
            shorter = sum(mine[k].path_length <= theirs[k].path_length for k in keep)
            lines.append(
                f"| {s} | {fam} | {homes} | {len(keep)} "
                f"| {_mean([mine[k].path_length for k in keep]):.2f} "
                f"| {_mean([theirs[k].path_length for k in keep]):.2f} "
                f"| {value:.3f} [{low:.3f}, {high:.3f}]{verdict} | {shorter} of {len(keep)} |"
            )
    if not compared:
        return [*lines[:-2], f"No strategy to compare: {MEMORYLESS} not run beside another."]
    if unpaired:
        lines += [
            "",
            "Runs left out, one of the two has no search that day: " + "; ".join(unpaired),
        ]
    return lines
