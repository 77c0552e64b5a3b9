"""``objsearch bench homes``: every strategy on homes we did not tune on, with schedules drawn from
AI2-THOR placement statistics (one schedule per seed)."""

from __future__ import annotations

import json
import statistics
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from objsearch.agent.errors import ObjsearchError
from objsearch.agent.home import available_homes
from objsearch.experiments.metrics import mean_std, summarise
from objsearch.experiments.runner import TARGETS, Job, Row, run_jobs, write_rows
from objsearch.experiments.strategies import STRATEGIES, strategy


def heldout_homes() -> tuple[str, ...]:
    """Every home but the paper's (which the paper's method, and our choices, were seen on)."""
    return tuple(h for h in available_homes() if h != "paper")


def family(home: str) -> str:
    return "procthor" if home.startswith("procthor") else "ithor"


def homes_jobs(
    homes: Sequence[str],
    strategies: Sequence[str],
    seeds: int,
    *,
    scenes: int | None = None,
    targets: Sequence[str] = TARGETS,
) -> list[Job]:
    known = set(available_homes())
    unknown = [h for h in homes if h not in known]
    if unknown:
        raise ObjsearchError(
            f"unknown home(s) {', '.join(unknown)}; available: {', '.join(sorted(known))}"
        )
    for name in strategies:
        strategy(name)
    scene_ids = tuple(range(1, scenes + 1)) if scenes else None
    jobs = []
    for home in homes:
        for seed in range(seeds):
            spec = f"stats-{seed}"
            for name in strategies:
                jobs.append(Job("homes", home, spec, name, "all", seed, tuple(targets), scene_ids))
            if "wpl" in strategies:
                jobs.append(
                    Job("homes", home, spec, "wpl", "none", seed, tuple(targets), scene_ids)
                )
    return jobs


def _key(r: Row) -> str:
    return r.strategy if r.update_mode == "all" else f"{r.strategy}/{r.update_mode}"


def homes_summary(rows: Sequence[Row]) -> dict[str, Any]:
    keys = list(dict.fromkeys(_key(r) for r in rows))
    out: dict[str, Any] = {"overall": {}, "by_family": {}, "by_home": {}}
    for k in keys:
        mine = [r for r in rows if _key(r) == k]
        # Spread over (home, schedule) runs: each run is one mean path length.
        runs = sorted({(r.home, r.seed) for r in mine})
        per_run = [
            statistics.fmean(r.path_length for r in mine if (r.home, r.seed) == hs) for hs in runs
        ]
        _, sd = mean_std(per_run)
        out["overall"][k] = {**summarise(mine), "runs": len(runs), "std_over_runs": sd}
        for fam in sorted({family(r.home) for r in mine}):
            out["by_family"].setdefault(fam, {})[k] = summarise(
                r for r in mine if family(r.home) == fam
            )
        for home in sorted({r.home for r in mine}):
            out["by_home"].setdefault(home, {})[k] = summarise(r for r in mine if r.home == home)
    # Wins: in how many (home, schedule) runs each strategy beats the paper's WPL.
    wpl: dict[tuple[str, int], list[float]] = {
        (r.home, r.seed): [] for r in rows if _key(r) == "wpl"
    }
    for r in rows:
        if _key(r) == "wpl":
            wpl[(r.home, r.seed)].append(r.path_length)
    for k in keys:
        wins = total = 0
        for hs, base in wpl.items():
            lengths = [r.path_length for r in rows if _key(r) == k and (r.home, r.seed) == hs]
            if lengths and base:
                total += 1
                wins += statistics.fmean(lengths) < statistics.fmean(base) - 1e-9
        out["overall"][k]["runs_better_than_wpl"] = f"{wins}/{total}"
    return out


def render(summary: dict[str, Any]) -> str:
    lines = [
        "Held-out homes — all searches (8 targets × every start × every scene), updates of all pairs"
    ]
    lines.append(
        f"{'strategy':20}{'n':>7}{'path m':>9}{'±runs':>7}{'success':>9}{'SPL':>7}{'oracle×':>9}{'< wpl':>8}"
    )
    for k, s in summary["overall"].items():
        lines.append(
            f"{k:20}{s['n']:7d}{s['mean_path_length']:9.2f}{s['std_over_runs']:7.2f}{s['success_rate']:9.1%}"
            f"{s['spl']:7.3f}{s['oracle_ratio']:9.2f}{s['runs_better_than_wpl']:>8}"
        )
    for fam, per in summary["by_family"].items():
        lines.append(f"\n{fam} homes: mean path length (m) / SPL")
        for k, s in per.items():
            lines.append(
                f"  {k:20}{s['mean_path_length']:8.2f}{s['spl']:8.3f}  success {s['success_rate']:.1%}"
            )
    return "\n".join(lines)


def run_homes(
    out: Path,
    *,
    homes: Sequence[str] | None,
    strategies: Sequence[str] | None,
    seeds: int = 1,
    scenes: int | None = None,
    workers: int = 2,
    progress: bool = True,
) -> dict[str, Any]:
    out.mkdir(parents=True, exist_ok=True)
    homes = list(homes) if homes else list(heldout_homes())
    strategies = list(strategies) if strategies else list(STRATEGIES)
    jobs = homes_jobs(homes, strategies, seeds, scenes=scenes)
    started = time.perf_counter()
    rows = run_jobs(jobs, workers=workers, progress=progress, label="bench homes")
    elapsed = time.perf_counter() - started
    parquet, csv = write_rows(rows, out, "homes_trials")
    summary = {
        "command": "objsearch bench homes",
        "homes": homes,
        "seeds": list(range(seeds)),
        "scenes": scenes or 10,
        "workers": workers,
        "elapsed_s": round(elapsed, 1),
        "searches": len(rows),
        **homes_summary(rows),
        "files": {"parquet": parquet.name, "csv": csv.name},
    }
    keys = ("mean_path_length", "success_rate", "spl", "oracle_ratio")
    summary["strategies"] = {k: {m: s[m] for m in keys} for k, s in summary["overall"].items()}
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    (out / "tables.txt").write_text(render(summary) + "\n", encoding="utf-8")
    return summary
