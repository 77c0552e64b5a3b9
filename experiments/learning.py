"""What a long-term run learned: the excess over the oracle by cause, and the *first search of the
day* — the first search for each target in each scene, the one that can only profit from earlier
scenes (the later ones also profit from the searches of the same scene) — as a learning curve."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from objsearch.experiments.runner import Row, inspection_suffix
from objsearch.experiments.stats import CI, MIN_RUNS, Spread, spread
from objsearch.experiments.strategies import COVER_SUFFIX


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


def first_of_scene(rows: Iterable[Row]) -> list[Row]:
    """The first search of each scene of each run: the search of the scene's first target in
    ``TARGET_ORDER`` among those searched (the robot has seen nothing of the scene yet). On a
    routine home, whose four scenes a day are four times of day, the first search of each slot."""
    from objsearch.sim.longterm import TARGET_ORDER

    order = {t: i for i, t in enumerate(TARGET_ORDER)}
    first: dict[tuple[Any, ...], Row] = {}
    for r in rows:
        k = (r.home, r.placements, r.strategy, r.update_mode, r.seed, r.scene)
        if k not in first or (order[r.target], r.task_id) < (
            order[first[k].target],
            first[k].task_id,
        ):
            first[k] = r
    return list(first.values())


def ratio(rows: Sequence[Row]) -> float:
    oracle = math.fsum(r.oracle_length for r in rows)
    return math.fsum(r.path_length for r in rows) / oracle if oracle > 0 else math.nan


def excess_breakdown(rows: Iterable[Row]) -> dict[str, float]:
    """Mean metres per successful search: the full path split into parts that are never negative
    (``wrong_rooms`` — of which ``start_room`` —, ``right_room`` before the final approach,
    ``approach``; they sum to ``path``), the oracle's walk and ``excess = path − oracle``.

    The oracle is shown beside the parts, not subtracted from one: its own walk crosses other
    rooms on the way to the target's room, so ``right room − oracle`` is often negative and a
    wrong-rooms share *of the excess* can pass 100 %. A share of the path cannot."""
    ok = [r for r in rows if r.success and r.wrong_rooms_m is not None]
    if not ok:
        return {"n": 0}
    n = len(ok)
    out: dict[str, float] = {"n": n}
    for part in ("wrong_rooms_m", "start_room_m", "approach_m"):
        out[part.removesuffix("_m")] = math.fsum(getattr(r, part) for r in ok) / n
    # Rows store the right room net of the oracle (experiments/decompose.py); add it back.
    out["right_room"] = math.fsum((r.right_room_m or 0.0) + r.oracle_length for r in ok) / n
    out["path"] = math.fsum(r.path_length for r in ok) / n
    out["oracle"] = math.fsum(r.oracle_length for r in ok) / n
    out["excess"] = out["path"] - out["oracle"]
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
                # None (null in summary.json, "–" in the table) when no scene is after ``after``.
                "all_ratio_after": ratio(late) if late else None,
                "first_ratio_after": ratio(first_of_day(late)) if late else None,
                "curve": curve(rs),
            }
        out[kind] = per
    return out


def render_paired(paired: dict[str, Spread], base: str = "wpl") -> str:
    lines = [
        f"\npath length minus {base}'s ({base}{COVER_SUFFIX}'s for a cover run), mean over "
        "(home, schedule, seed) runs (m), "
        f"{CI} or, under {MIN_RUNS} runs, the range"
    ]
    for k, d in paired.items():
        lines.append(f"  {k:22}{d.mean:+8.2f}  {d.text()}  runs {d.n}")
    return "\n".join(lines)


def full_path(row: Row) -> float:
    return row.path_length


def run_of(r: Row) -> tuple[str, str, int]:
    """The run a search belongs to: (home, schedule with its seed, strategy seed)."""
    return (r.home, r.placements, r.seed)


def paired_differences(
    rows: Sequence[Row],
    *,
    base: str = "wpl",
    metric: Callable[[Row], float] = full_path,
) -> dict[str, Spread]:
    """Per strategy: over the runs both it and ``base`` made, its run mean ``metric`` minus
    ``base``'s, summarised by :func:`experiments.stats.spread` (a 95 % interval only over enough
    runs). ``base`` is taken with each strategy's own inspection: a ``+cover`` run pairs with
    ``wpl+cover`` (``--inspection cover`` names every strategy so), never with plain ``wpl``."""
    means: dict[tuple[str, str, str], list[float]] = {}
    for r in rows:
        means.setdefault((key(r), r.home, r.placements), []).append(metric(r))
    run_mean = {k: math.fsum(v) / len(v) for k, v in means.items()}
    out: dict[str, Spread] = {}
    for k in dict.fromkeys(key(r) for r in rows):
        own_base = base + inspection_suffix(k.partition("/")[0])
        diffs = [
            m - run_mean[(own_base, home, spec)]
            for (kk, home, spec), m in sorted(run_mean.items())
            if kk == k and (own_base, home, spec) in run_mean
        ]
        if diffs and k != own_base:
            out[k] = spread(diffs)
    return out


def paired_json(paired: dict[str, Spread]) -> dict[str, dict[str, Any]]:
    """summary.json's ``paired_vs_wpl``: ``ci_low``/``ci_high`` only where there is an interval."""
    out: dict[str, dict[str, Any]] = {}
    for k, d in paired.items():
        doc: dict[str, Any] = {"runs": d.n, "mean_diff_m": d.mean, "spread": d.kind}
        if d.is_interval:
            doc |= {"ci_low": d.low, "ci_high": d.high}
        else:
            doc |= {"min": d.low, "max": d.high}
        out[k] = doc
    return out


def render_learning(summary: dict[str, Any], *, after: int = 10) -> str:
    lines: list[str] = []
    for kind, per in summary.items():
        lines.append(
            f"\n{kind} schedules: full path of a successful search by where it went, and the "
            "oracle beside it (m; parts sum to the path)"
        )
        lines.append(
            f"  {'strategy':22}{'path':>7}{'oracle':>8}{'excess':>8}{'wrong rm':>9}{'(start)':>9}"
            f"{'right rm':>9}{'approach':>9}{'all×':>7}{'first×':>8}{f'all×>{after}':>9}"
            f"{f'1st×>{after}':>9}"
        )
        for k, s in per.items():
            e = s["excess"]
            if not e.get("n"):
                continue
            lines.append(
                f"  {k:22}{e['path']:7.2f}{e['oracle']:8.2f}{e['excess']:8.2f}"
                f"{e['wrong_rooms']:9.2f}{e['start_room']:9.2f}{e['right_room']:9.2f}"
                f"{e['approach']:9.2f}{s['all_ratio']:7.2f}{s['first_ratio']:8.2f}"
                f"{_or_dash(s['all_ratio_after'], 9)}{_or_dash(s['first_ratio_after'], 9)}"
            )
    return "\n".join(lines)


def _or_dash(value: float | None, width: int) -> str:
    """A ratio to 2 decimals, or "–" where there is none (no scene after the cut; was "nan")."""
    return (
        f"{value:{width}.2f}" if value is not None and math.isfinite(value) else f"{'–':>{width}}"
    )


def run_curves(rows: Sequence[Row]) -> dict[str, dict[int, list[float]]]:
    """Per scene, each run's Σ path / Σ oracle (all searches, and first searches of the day)."""
    out: dict[str, dict[int, list[float]]] = {"all": {}, "first": {}}
    for which, group in (("all", list(rows)), ("first", first_of_day(rows))):
        cells: dict[tuple[int, tuple[str, str, int]], list[Row]] = {}
        for r in group:
            cells.setdefault((r.scene, run_of(r)), []).append(r)
        for (scene, _), rs in sorted(cells.items()):
            value = ratio(rs)
            if not math.isnan(value):
                out[which].setdefault(scene, []).append(value)
    return out


#: Bootstrap resamples for a curve's band at each scene (a picture, not a table figure).
BAND_RESAMPLES = 2_000


def plot_curves(
    rows: Sequence[Row], out: Path, *, prefix: str = "learning", base: str = "wpl"
) -> list[Path]:
    """One figure per schedule kind (``<prefix>_<kind>.png``, with .svg and .pdf beside it): a
    panel per strategy, the first search of the day as the mean over runs with its band (95 %
    CI with enough runs, else the runs' range: experiments/stats.py), all searches dashed, and
    ``base``'s first-search curve in grey in every other panel for reference."""
    from objsearch.experiments.plots import pyplot, save_figure

    plt = pyplot()
    from matplotlib.ticker import MaxNLocator

    paths: list[Path] = []
    for kind in sorted({r.placements.partition("-")[0] for r in rows}):
        mine = [r for r in rows if r.placements.partition("-")[0] == kind]
        keys = list(dict.fromkeys(key(r) for r in mine))
        curves = {k: run_curves([r for r in mine if key(r) == k]) for k in keys}
        cols = min(3, len(keys))
        nrows = math.ceil(len(keys) / cols)
        fig, axes = plt.subplots(
            nrows, cols, figsize=(3.2 * cols, 2.4 * nrows + 0.6), sharex=True, sharey=True,
            squeeze=False,
        )  # fmt: skip
        kinds_drawn: set[str] = set()
        for i, k in enumerate(keys):
            ax = axes[i // cols][i % cols]
            # The reference of the panel's own inspection (wpl+cover for a cover run).
            own_base = base + inspection_suffix(k.partition("/")[0])
            if own_base in curves and k != own_base:
                ref = sorted(curves[own_base]["first"].items())
                ax.plot(
                    [s for s, _ in ref],
                    [math.fsum(v) / len(v) for _, v in ref],
                    color="0.6",
                    lw=1,
                    label=f"{own_base}, first search (reference)",
                )
            runs = 0
            for which, style in (("first", "-"), ("all", "--")):
                pts = sorted(curves[k][which].items())
                spreads = [spread(v, resamples=BAND_RESAMPLES) for _, v in pts]
                scenes = [s for s, _ in pts]
                ax.plot(
                    scenes,
                    [d.mean for d in spreads],
                    style,
                    color="C0" if which == "first" else "C1",
                    lw=1.5,
                    label="first search of the day" if which == "first" else "all searches",
                )
                if which == "first" and spreads:
                    runs = max(d.n for d in spreads)
                    kinds_drawn |= {d.kind for d in spreads}
                    ax.fill_between(
                        scenes,
                        [d.low for d in spreads],
                        [d.high for d in spreads],
                        color="C0",
                        alpha=0.2,
                        lw=0,
                        label="band (first search)",
                    )
            ax.set_title(f"{k} ({runs} run{'s' if runs != 1 else ''})")
            if i % cols == 0:
                ax.set_ylabel("path / oracle path (×)")
            if i // cols == nrows - 1 or i + cols >= len(keys):
                ax.set_xlabel("scene (day)")
                ax.tick_params(labelbottom=True)
        axes[0][0].xaxis.set_major_locator(MaxNLocator(integer=True))
        for j in range(len(keys), nrows * cols):
            axes[j // cols][j % cols].set_visible(False)
        band = " or ".join(sorted(kinds_drawn)) or "none"
        fig.suptitle(
            f"{kind} schedules: mean over runs of each run's Σ path / Σ oracle per scene; "
            f"band: {band} over runs (CI only with ≥ {MIN_RUNS} runs)",
            fontsize=9,
        )
        handles, labels = [], []
        for ax in axes.flat:
            for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
                if lab not in labels:
                    handles.append(h)
                    labels.append(lab)
        fig.legend(handles, labels, loc="lower center", ncol=len(labels), frameon=False)
        fig.tight_layout(rect=(0, 0.06 + 0.02 / nrows, 1, 0.95))
        path = out / f"{prefix}_{kind}.png"
        save_figure(fig, path)
        paths.append(path)
    return paths
