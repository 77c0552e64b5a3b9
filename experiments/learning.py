"""What a long-term run learned: the excess over the oracle by cause, and the *first search of the
day* — the first search for each target in each scene, the one that can only profit from earlier
scenes (the later ones also profit from the searches of the same scene) — as a learning curve."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from objsearch.experiments.runner import Row

_PARTS = ("wrong_rooms_m", "start_room_m", "right_room_m", "approach_m")


def key(r: Row) -> str:
    return r.strategy if r.update_mode == "all" else f"{r.strategy}/{r.update_mode}"


def first_of_day(rows: Iterable[Row]) -> list[Row]:
    """The first search for each target in each scene of each run (lowest task id)."""
    first: dict[tuple[Any, ...], Row] = {}
    for r in rows:
        k = (r.home, r.placements, r.strategy, r.update_mode, r.seed, r.scene, r.target)
        if k not in first or r.task_id < first[k].task_id:
            first[k] = r
    return list(first.values())


def ratio(rows: Sequence[Row]) -> float:
    oracle = math.fsum(r.oracle_length for r in rows)
    return math.fsum(r.path_length for r in rows) / oracle if oracle > 0 else math.nan


def excess_breakdown(rows: Iterable[Row]) -> dict[str, float]:
    """Mean metres per successful search of each part of the excess (they sum to ``excess``)."""
    ok = [r for r in rows if r.success and r.wrong_rooms_m is not None]
    if not ok:
        return {"n": 0}
    out: dict[str, float] = {"n": len(ok)}
    for part in _PARTS:
        out[part.removesuffix("_m")] = math.fsum(getattr(r, part) for r in ok) / len(ok)
    out["excess"] = math.fsum(r.path_length - r.oracle_length for r in ok) / len(ok)
    return out


def curve(rows: Sequence[Row]) -> dict[str, dict[int, float]]:
    """Per scene, Σ path / Σ oracle of all searches and of the first searches of the day."""
    scenes = sorted({r.scene for r in rows})
    firsts = first_of_day(rows)
    return {
        "all": {s: ratio([r for r in rows if r.scene == s]) for s in scenes},
        "first": {s: ratio([r for r in firsts if r.scene == s]) for s in scenes},
    }


def learning_summary(rows: Sequence[Row], *, after: int = 10) -> dict[str, Any]:
    """Per strategy (and schedule kind): excess by cause, first-of-day and all-search oracle
    ratios overall and after scene ``after``, and the learning curves."""
    out: dict[str, Any] = {}
    for kind in sorted({r.placements.partition("-")[0] for r in rows}):
        per: dict[str, Any] = {}
        mine = [r for r in rows if r.placements.partition("-")[0] == kind]
        for k in dict.fromkeys(key(r) for r in mine):
            rs = [r for r in mine if key(r) == k]
            late = [r for r in rs if r.scene > after]
            per[k] = {
                "excess": excess_breakdown(rs),
                "all_ratio": ratio(rs),
                "first_ratio": ratio(first_of_day(rs)),
                "all_ratio_after": ratio(late) if late else math.nan,
                "first_ratio_after": ratio(first_of_day(late)) if late else math.nan,
                "curve": curve(rs),
            }
        out[kind] = per
    return out


def render_paired(paired: dict[str, dict[str, float]], base: str = "wpl") -> str:
    lines = [
        f"\npath length minus {base}'s, per (home, schedule) run (m), paired bootstrap 95 % CI"
    ]
    for k, d in paired.items():
        lines.append(
            f"  {k:22}{d['mean_diff_m']:+8.2f}  [{d['ci_low']:+.2f}, {d['ci_high']:+.2f}]"
            f"  runs {d['runs']:g}"
        )
    return "\n".join(lines)


def full_path(row: Row) -> float:
    return row.path_length


def paired_bootstrap(
    rows: Sequence[Row],
    *,
    base: str = "wpl",
    resamples: int = 10_000,
    seed: int = 0,
    metric: Callable[[Row], float] = full_path,
) -> dict[str, dict[str, float]]:
    """Per strategy: the mean over (home, schedule) runs of (its run mean ``metric`` − ``base``'s),
    with a paired bootstrap 95 % CI over runs (resampling runs with replacement, seeded)."""
    import random

    means: dict[tuple[str, str, str], list[float]] = {}
    for r in rows:
        means.setdefault((key(r), r.home, r.placements), []).append(metric(r))
    run_mean = {k: math.fsum(v) / len(v) for k, v in means.items()}
    out: dict[str, dict[str, float]] = {}
    rng = random.Random(seed)
    for k in dict.fromkeys(key(r) for r in rows):
        diffs = [
            m - run_mean[(base, home, spec)]
            for (kk, home, spec), m in sorted(run_mean.items())
            if kk == k and (base, home, spec) in run_mean
        ]
        if not diffs or k == base:
            continue
        boot = sorted(
            math.fsum(rng.choice(diffs) for _ in diffs) / len(diffs) for _ in range(resamples)
        )
        out[k] = {
            "runs": len(diffs),
            "mean_diff_m": math.fsum(diffs) / len(diffs),
            "ci_low": boot[int(0.025 * resamples)],
            "ci_high": boot[int(0.975 * resamples) - 1],
        }
    return out


def render_learning(summary: dict[str, Any], *, after: int = 10) -> str:
    lines: list[str] = []
    for kind, per in summary.items():
        lines.append(f"\n{kind} schedules: excess over the oracle per successful search (m)")
        lines.append(
            f"  {'strategy':22}{'excess':>8}{'wrong rm':>9}{'(start)':>9}{'right rm':>9}"
            f"{'approach':>9}{'all×':>7}{'first×':>8}{f'all×>{after}':>9}{f'1st×>{after}':>9}"
        )
        for k, s in per.items():
            e = s["excess"]
            if not e.get("n"):
                continue
            lines.append(
                f"  {k:22}{e['excess']:8.2f}{e['wrong_rooms']:9.2f}{e['start_room']:9.2f}"
                f"{e['right_room']:9.2f}{e['approach']:9.2f}{s['all_ratio']:7.2f}"
                f"{s['first_ratio']:8.2f}{s['all_ratio_after']:9.2f}{s['first_ratio_after']:9.2f}"
            )
    return "\n".join(lines)


def plot_curves(summary: dict[str, Any], out: Path, *, prefix: str = "learning") -> list[Path]:
    """One PNG per schedule kind (``<prefix>_<kind>.png``): oracle ratio per scene, first search
    of the day (solid) and all searches (dashed), per strategy."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths: list[Path] = []
    for kind, per in summary.items():
        fig, ax = plt.subplots(figsize=(7, 4))
        for i, (k, s) in enumerate(per.items()):
            color = f"C{i % 10}"
            for which, style in (("first", "-"), ("all", "--")):
                pts = sorted((int(x), y) for x, y in s["curve"][which].items())
                ax.plot(
                    [p[0] for p in pts],
                    [p[1] for p in pts],
                    style,
                    color=color,
                    label=f"{k} ({which})",
                )
        ax.set_xlabel("scene (day)")
        ax.set_ylabel("path / oracle path")
        ax.set_title(f"{kind} schedules: first search of the day (solid) vs all (dashed)")
        ax.legend(fontsize=6, ncol=2)
        fig.tight_layout()
        path = out / f"{prefix}_{kind}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths
