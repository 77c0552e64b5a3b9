"""``objsearch bench report --rearr``: docs/results-rearrangement.md from a ``bench homes`` run with
``--schedules rearr[,stats]`` (schedules taken from real AI2-THOR rearrangement episodes)."""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from objsearch.agent.errors import ObjsearchError
from objsearch.agent.home import load_home
from objsearch.experiments.homes import homes_summary, schedule_kind
from objsearch.experiments.runner import Row, read_rows
from objsearch.sim.schedule_names import load_schedule

RESULTS_FILE = "results-rearrangement.md"


def load_rows(folder: Path) -> tuple[dict[str, Any], list[Row]]:
    """The run's summary.json (its command line) and its rows, from which everything is recomputed."""
    path = folder / "summary.json"
    if not path.is_file():
        raise ObjsearchError(f"no bench summary at {path}; run `objsearch bench homes` first")
    summary: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    rows = read_rows(folder / summary["files"]["parquet"])
    if not any(schedule_kind(r.placements) == "rearr" for r in rows):
        raise ObjsearchError(f"{folder} has no rearr-<seed> runs; run with --schedules rearr,stats")
    return summary, rows


def schedule_moves(
    homes: Sequence[str], kind: str, seeds: Sequence[int], scenes: int
) -> dict[str, Any]:
    """How the schedules move objects: share of scene-to-scene steps where an object changes its
    static, and where it changes room; and the classes a rearr schedule takes from stats."""
    steps = static_moves = room_moves = 0
    fallback: dict[str, list[str]] = {}
    for name in homes:
        home = load_home(name)
        for seed in seeds:
            schedule = load_schedule(home, f"{kind}-{seed}", scenes=scenes)
            if schedule.fallback:
                fallback[name] = sorted(set(fallback.get(name, [])) | set(schedule.fallback))
            for k in range(2, scenes + 1):
                before = {p.cls: p for p in schedule.scenes[k - 1].values()}
                for p in schedule.scenes[k].values():
                    if p.cls in schedule.fallback or p.cls not in before:
                        continue
                    steps += 1
                    static_moves += p.support != before[p.cls].support
                    room_moves += p.room != before[p.cls].room
    return {
        "steps": steps,
        "static": static_moves / steps if steps else math.nan,
        "room": room_moves / steps if steps else math.nan,
        "fallback": fallback,
    }


def _table(per: dict[str, Any]) -> list[str]:
    lines = [
        f"{'strategy':20}{'n':>7}{'path m':>9}{'±runs':>7}{'±seeds':>8}{'success':>9}{'SPL':>7}"
        f"{'oracle×':>9}{'< wpl':>8}"
    ]
    for k, s in per.items():
        lines.append(
            f"{k:20}{s['n']:7d}{s['mean_path_length']:9.2f}{s['std_over_runs']:7.2f}"
            f"{s['std_over_seeds']:8.2f}{s['success_rate']:9.1%}{s['spl']:7.3f}"
            f"{s['oracle_ratio']:9.2f}{s.get('runs_better_than_wpl', ''):>8}"
        )
    return lines


def _change(a: float, b: float) -> str:
    return f"{100 * (a - b) / b:+.1f} %"


def _per_home(summary: dict[str, Any], kinds: Sequence[str]) -> list[str]:
    """Mean path length per home, one column per strategy, the schedule kinds' values in each."""
    keys = list(summary["overall"])
    per_home = [f"{'home':12}" + "".join(f"{k:>20}" for k in keys)]
    for home, per in summary["by_home_schedule"].items():
        cells = (
            " / ".join(f"{per.get(kind, {}).get(k, math.nan):.2f}" for kind in kinds) for k in keys
        )
        per_home.append(f"{home:12}" + "".join(f"{c:>20}" for c in cells))
    return per_home


def _notes(summary: dict[str, Any], rows: Sequence[Row], kinds: Sequence[str]) -> list[str]:
    """The page's reading: each kind against WPL without updates, rearr against stats, the
    stats-0 cross-check, and the failed searches by target."""
    failed = {
        kind: Counter(
            r.target for r in rows if not r.success and schedule_kind(r.placements) == kind
        )
        for kind in kinds
    }
    by = summary["by_schedule"]
    notes = []
    for kind in kinds:
        base = by[kind].get("wpl/none", {}).get("mean_path_length", math.nan)
        gains = ", ".join(
            f"{k} {_change(s['mean_path_length'], base)}"
            for k, s in by[kind].items()
            if k != "wpl/none"
        )
        best = min(by[kind], key=lambda k: by[kind][k]["mean_path_length"])
        notes.append(
            f"- **{kind}**: against WPL without updates ({base:.2f} m): {gains}; lowest mean path "
            f"length **{best}** ({by[kind][best]['mean_path_length']:.2f} m)."
        )
    if "stats" in by:
        common = [k for k in by["rearr"] if k in by["stats"]]
        notes.append(
            "- **rearr vs stats** (same homes, seeds, scenes): "
            + ", ".join(
                f"{k} {by['rearr'][k]['mean_path_length']:.2f} vs "
                f"{by['stats'][k]['mean_path_length']:.2f} m ({_change(by['rearr'][k]['mean_path_length'], by['stats'][k]['mean_path_length'])})"
                for k in common
            )
            + "."
        )
        stats0 = homes_summary([r for r in rows if r.placements == "stats-0"])["overall"]
        notes.append(
            "- Cross-check: the `stats-0` runs alone give "
            + ", ".join(f"{k} {s['mean_path_length']:.2f} m" for k, s in stats0.items())
            + '; compare docs/results.md\'s "ithor homes" rows (the same `stats-0` schedules '
            "when that run used these homes and scenes)."
        )
    notes.append(
        "- Failed searches by target: "
        + "; ".join(
            f"{kind}: " + (", ".join(f"{t} {n}" for t, n in c.most_common()) or "none")
            for kind, c in failed.items()
        )
        + " (every strategy and start counted)."
    )
    return notes


def render_rearr(run: dict[str, Any], rows: Sequence[Row], folder: Path) -> str:
    summary = homes_summary(rows)
    kinds = list(summary["by_schedule"])
    seeds = sorted({r.seed for r in rows})
    homes = list(run["homes"])
    scenes = int(run["scenes"])
    strategies = list(dict.fromkeys(r.strategy for r in rows if r.update_mode == "all"))
    cmd = (
        f"objsearch bench homes --out {folder} --homes {','.join(homes)} "
        f"--schedules {','.join(run.get('schedules', kinds))} --seeds {len(seeds)} "
        f"--scenes-per-schedule {scenes} --strategies {','.join(strategies)} --workers {run['workers']}"
    )
    moves = {k: schedule_moves(homes, k, seeds, scenes) for k in kinds}
    rearr = moves["rearr"]
    fallback_lines = [
        f"- {home}: {', '.join(classes)}" for home, classes in sorted(rearr["fallback"].items())
    ]
    tables: list[str] = []
    for kind in kinds:
        tables += [
            f"{kind} schedules ({kind}-<seed>, seeds {seeds})",
            *_table(summary["by_schedule"][kind]),
            "",
        ]
    per_home = _per_home(summary, kinds)
    notes = _notes(summary, rows, kinds)
    move_lines = [
        f"- {kind}: an object changes its static in {m['static']:.0%} and its room in "
        f"{m['room']:.0%} of {m['steps']} scene-to-scene steps"
        + (" (classes taken from the stats draw left out)" if kind == "rearr" else "")
        for kind, m in moves.items()
    ]
    return f"""# Results — schedules from real rearrangement episodes

Generated by `objsearch bench report --rearr {folder}` from the output of the command below; do not
edit by hand. It complements docs/results.md (the paper home and the `stats-<seed>` held-out run);
docs/paper-readings.md says how a `rearr-<seed>` schedule is read from the episodes.

## Command and seeds
```
{cmd}
#   {run["searches"]} searches, {run["elapsed_s"]} s with {run["workers"]} processes (shared, loaded machine)
objsearch bench report --rearr {folder}
```
Schedules: {", ".join(f"`{k}-<seed>`" for k in kinds)} for seeds {seeds}, the first {scenes} scenes of
each, on {len(homes)} homes ({", ".join(homes)}). `rearr-<seed>` (`sim/rearr_schedule.py`) takes
each scene's placements from real AI2-THOR rearrangement episodes of the home's FloorPlans
(`data/rearrangement/`): per room an episode drawn by the seeded RNG, its target poses in scene
2j-1 and its starting poses in scene 2j. Classes without rearrangement data in a home are placed by
the `stats-<seed>` draw with the same seed:
{chr(10).join(fallback_lines) or "- none"}

How the schedules move objects:
{chr(10).join(move_lines)}

## Results
Every strategy with updates of all pairs, and WPL without updates (`wpl/none`); 8 targets × every
start × every scene. `±runs`: standard deviation of the mean path length over (home, schedule)
runs; `±seeds`: over seeds (each the mean over homes). `< wpl`: runs where the strategy's mean path
length is below WPL's.
```
{chr(10).join(tables).rstrip()}
```
Mean path length (m) per home, mean over seeds ({" / ".join(kinds)}):
```
{chr(10).join(per_home)}
```

## Reading
{chr(10).join(notes)}
"""


def write_rearr_report(folder: Path, out: Path) -> Path:
    run, rows = load_rows(folder)
    out.write_text(render_rearr(run, rows, folder), encoding="utf-8")
    return out


__all__ = ["RESULTS_FILE", "write_rearr_report"]
