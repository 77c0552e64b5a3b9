"""``objsearch bench belief DIR [DIR ...]``: the belief's figures from ``bench homes`` outputs
(docs/results-belief.md's protocol): first search of the day against the distribution oracle with
bootstrap CIs over runs, paired differences, what a moved habit costs day by day, the calibration
of the belief's forecasts, success and failures, and learning curves with CI bands.

A *run* is one (home, schedule) pair of one strategy; every interval resamples runs with
replacement (10 000 resamples, seed 0) and is shown only with at least ``MIN_RUNS`` runs (below
that: n and the range of the run values).

The outputs read together must have been run with one simulated detector and one localisation
(their summary.json's ``perception`` and ``localisation`` presets; :func:`run_models`), so the
calibration of ``where`` is reported under a named model; ``--perception`` and
``--localisation`` say which one is expected (:func:`select_models`).
"""

from __future__ import annotations

import json
import math
import random
from collections.abc import Callable, Iterable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from objsearch.agent.errors import ObjsearchError
from objsearch.experiments.calibration import ece
from objsearch.experiments.learning import first_of_day, first_of_scene, ratio
from objsearch.experiments.metrics import spl_term
from objsearch.experiments.report_data import HomeFolders, home_folders
from objsearch.experiments.runner import Row, inspection_suffix, read_output
from objsearch.experiments.strategies import COVER_SUFFIX
from objsearch.sim.schedule_names import ROUTINE_KINDS

AFTER = 10
#: routine-<seed> and homer-<seed>: the evaluation scenes are those after day 14 (four scenes a day,
#: sim/routine_schedule.py; docs/results-routine.md).
ROUTINE_AFTER = 14 * 4
#: The scenes' slots of a seeded schedule, in order (sim/routine_schedule.py SLOT_NAMES).
SLOT_NAMES = ("morning", "afternoon", "evening", "night")
MIN_RUNS = 10
RESAMPLES = 10_000
ORACLE = "dist-oracle"
#: The references: the distribution oracle planned room by room and over the whole home. A table's
#: reference is whichever walks less on its rows (the oracle plans with the best planner).
REFERENCES = (ORACLE, "dist-oracle-global")
#: The comparisons every report makes, each within one inspection (``a+cover`` with ``b+cover``).
PAIRS = (
    ("ecost-belief", "ecost-memory"),
    ("ecost-belief", ORACLE),
    ("ecost-belief", "ecost"),
    ("ecost-routine", "ecost-belief"),
    ("ecost-routine", ORACLE),
    ("ecost-routine-pooled", "ecost-routine"),
    ("ecost-routine-pooled", "ecost-belief"),
    ("ecost-routine-pooled", ORACLE),
    ("global-belief", "ecost-belief"),
    ("global-belief", "dist-oracle-global"),
    ("dist-oracle-global", ORACLE),
)


def _references(strategies: Sequence[str]) -> list[str]:
    return [s for s in strategies if s.partition("+")[0] in REFERENCES]


#: moved-<seed>: the first scene with new habits (sim/habit_schedule.py MOVE_SCENE).
MOVE_SCENE = 11


def kind(r: Row) -> str:
    return r.placements.partition("-")[0]


def _runs(rows: Sequence[Row]) -> dict[tuple[str, str], list[Row]]:
    out: dict[tuple[str, str], list[Row]] = {}
    for r in rows:
        out.setdefault((r.home, r.placements), []).append(r)
    return out


def _boot(
    keys: Sequence[tuple[str, str]],
    stat: Callable[[Sequence[tuple[str, str]]], float],
    seed: int = 0,
) -> tuple[float, float]:
    rng = random.Random(seed)
    values = sorted(stat([rng.choice(keys) for _ in keys]) for _ in range(RESAMPLES))
    return values[int(0.025 * RESAMPLES)], values[int(0.975 * RESAMPLES) - 1]


def _interval(value: float, low: float, high: float, n: int) -> str:
    return f"{value:.3f} [{low:.3f}, {high:.3f}]" if n >= MIN_RUNS else f"{value:.3f} (n={n})"


def after_scene(k: str) -> int:
    """The last scene before a kind's evaluation scenes."""
    return ROUTINE_AFTER if k in ROUTINE_KINDS else AFTER


def _spl(rows: Sequence[Row]) -> float:
    return math.fsum(spl_term(r) for r in rows) / len(rows) if rows else math.nan


def ratio_table(rows: Sequence[Row], after: int = AFTER) -> list[str]:
    """Per strategy: first-of-day oracle× after ``after``, and its ratio to the oracle's, with
    CIs over runs (paired: the same runs resampled for both); success and SPL (Anderson et al.
    2018) of the first searches after ``after``."""
    late = [r for r in first_of_day(rows) if r.scene > after]
    by = {
        s: _runs([r for r in late if r.strategy == s])
        for s in dict.fromkeys(r.strategy for r in rows)
    }
    present = _references([s for s in by if by[s]])
    reference = min(
        present,
        key=lambda s: ratio([r for rs in by[s].values() for r in rs]),
        default=ORACLE,
    )
    lines = [
        f"| strategy | first× all | first× after scene {after} | ÷ {reference} after scene {after} "
        f"| success | searches | success after {after} | SPL after {after} |",
        "|---|---|---|---|---|---|---|---|",
    ]
    oracle = by.get(reference, {})
    firsts = first_of_day(rows)
    for s, runs in by.items():
        keys = sorted(runs)
        if not keys:
            continue

        def own(
            ks: Sequence[tuple[str, str]], runs: dict[tuple[str, str], list[Row]] = runs
        ) -> float:
            return ratio([r for k in ks for r in runs[k]])

        mine = [r for r in firsts if r.strategy == s]
        lo, hi = _boot(keys, own)
        cell = _interval(own(keys), lo, hi, len(keys))
        vs = "–"
        shared = [k for k in keys if k in oracle]
        if s != reference and shared:

            def rel(
                ks: Sequence[tuple[str, str]], runs: dict[tuple[str, str], list[Row]] = runs
            ) -> float:
                return ratio([r for k in ks for r in runs[k]]) / ratio(
                    [r for k in ks for r in oracle[k]]
                )

            lo2, hi2 = _boot(shared, rel)
            vs = _interval(rel(shared), lo2, hi2, len(shared))
        success = sum(r.success for r in mine) / len(mine)
        evaluated = [r for k in keys for r in runs[k]]
        late_success = sum(r.success for r in evaluated) / len(evaluated)
        lines.append(
            f"| {s} | {ratio(mine):.3f} | {cell} | {vs} | {success:.2%} | {len(mine)} "
            f"| {late_success:.2%} | {_spl(evaluated):.3f} |"
        )
    if not late:  # a header with no row said nothing
        last = max((r.scene for r in rows), default=0)
        return [
            f"(no search after scene {after} to tabulate: these runs end at scene {last}; "
            "bench homes --scenes-per-schedule sets a run's length)"
        ]
    return lines


def paired_lines(
    rows: Sequence[Row], pairs: Sequence[tuple[str, str]], after: int = AFTER
) -> list[str]:
    """Mean over runs of (a's − b's mean first-of-day full path, after ``after``), metres, CI."""
    late = [r for r in first_of_day(rows) if r.scene > after]
    means: dict[tuple[str, str, str], float] = {}
    for (home, spec), rs in _runs(late).items():
        for s in {r.strategy for r in rs}:
            mine = [r.path_length for r in rs if r.strategy == s]
            means[(s, home, spec)] = math.fsum(mine) / len(mine)
    lines = [
        f"| a − b (first search, after day {after}, m) | runs | mean | 95 % CI |",
        "|---|---|---|---|",
    ]
    for a, b in pairs:
        diffs = [
            means[(a, h, sp)] - means[(b, h, sp)]
            for (s, h, sp) in sorted(means)
            if s == a and (b, h, sp) in means
        ]
        if not diffs:
            continue
        rng = random.Random(0)
        boot = sorted(
            math.fsum(rng.choice(diffs) for _ in diffs) / len(diffs) for _ in range(RESAMPLES)
        )
        mean = math.fsum(diffs) / len(diffs)
        ci = (
            f"[{boot[int(0.025 * RESAMPLES)]:.2f}, {boot[int(0.975 * RESAMPLES) - 1]:.2f}]"
            if len(diffs) >= MIN_RUNS
            else f"n={len(diffs)}: range [{min(diffs):.2f}, {max(diffs):.2f}]"
        )
        lines.append(f"| {a} − {b} | {len(diffs)} | {mean:.2f} | {ci} |")
    if len(lines) == 2:  # a header with no row said nothing
        names = {r.strategy for r in rows}
        near = [(a, b) for a, b in pairs if a in names or b in names] or list(pairs)
        held = ", ".join(sorted(names))
        compared = ", ".join(f"{a} − {b}" for a, b in near)
        return [
            f"(no pair to compare after day {after}: a − b needs both in the same runs, "
            f"for {compared}; these outputs hold {held})"
        ]
    return lines


def slot_lines(rows: Sequence[Row], after: int = ROUTINE_AFTER) -> list[str]:
    """Per strategy and slot of the day (scene n is slot (n − 1) mod 4): first-search oracle×
    after ``after``, and its ratio to the oracle's."""
    late = [r for r in first_of_day(rows) if r.scene > after]
    lines = [
        f"| strategy (first× after scene {after}) | "
        + " | ".join(SLOT_NAMES)
        + " | weekend days |",
        "|---|" + "---|" * (len(SLOT_NAMES) + 1),
    ]
    for s in dict.fromkeys(r.strategy for r in late):
        mine = [r for r in late if r.strategy == s]
        cells = [
            ratio([r for r in mine if (r.scene - 1) % len(SLOT_NAMES) == k])
            for k in range(len(SLOT_NAMES))
        ]
        weekend = [r for r in mine if ((r.scene - 1) // len(SLOT_NAMES)) % 7 in (5, 6)]
        shown = [*cells, ratio(weekend) if weekend else math.nan]
        lines.append(
            f"| {s} | " + " | ".join("–" if math.isnan(c) else f"{c:.3f}" for c in shown) + " |"
        )
    return lines


def first_of_scene_lines(rows: Sequence[Row], after: int = ROUTINE_AFTER) -> list[str]:
    """Routine kinds: the same table and pairs on the first search of each scene (each slot of
    the day: nothing of it seen yet; docs/results-routine.md says why a routine home is judged
    by it), and on the first search of each day (the morning scene's first search)."""
    firsts = first_of_scene(rows)
    mornings = [r for r in firsts if (r.scene - 1) % len(SLOT_NAMES) == 0]
    pairs = [(a, b) for a, b in PAIRS if a.startswith("ecost-routine")]
    pairs.append(("slot-oracle", ORACLE))
    return [
        "First search of each scene (one a time of day, four a day):",
        "",
        *ratio_table(firsts, after),
        "",
        *paired_lines(firsts, pairs, after),
        "",
        "First search of each day (the morning scene's first search):",
        "",
        *ratio_table(mornings, after),
    ]


def usual_place_lines(
    rows: Sequence[Row], after: int = AFTER, data: HomeFolders | None = None
) -> list[str]:
    """``habit`` schedules: the first search of the day after ``after`` on the days the target
    was at its usual place (the schedule drawn again from its seed), per strategy: oracle× and its
    ratio to the reference's on the same searches. ``data``: the data folder of each home
    (experiments/report_data.py; None: the process's)."""
    from objsearch.agent.home import load_home
    from objsearch.sim.habit_schedule import habit_schedule, habits

    late = [r for r in first_of_day(rows) if r.scene > after and kind(r) == "habit"]
    usual_days: set[tuple[str, str, int, str]] = set()
    for home, placements in sorted({(r.home, r.placements) for r in late}):
        seed = int(placements.partition("-")[2])
        last = max(r.scene for r in late if (r.home, r.placements) == (home, placements))
        folder = data.get(home) if data else None
        house = load_home(home, folder)
        table = habits(house, seed, folder)
        schedule = habit_schedule(house, seed, scenes=last, data=folder)
        for scene, placed in schedule.scenes.items():
            for p in placed.values():
                if p.cls in table and p.support == table[p.cls].usual:
                    usual_days.add((home, placements, scene, p.cls))
    mine = [r for r in late if (r.home, r.placements, r.scene, r.target) in usual_days]
    if not mine:
        return []
    by = {s: [r for r in mine if r.strategy == s] for s in dict.fromkeys(r.strategy for r in mine)}
    present = _references([s for s in by if by[s]])
    reference = min(present, key=lambda s: ratio(by[s]), default=None)
    lines = [
        f"On days the target was at its usual place (first search after day {after}):",
        "",
        f"| strategy | searches | oracle× | ÷ {reference or 'reference'} |",
        "|---|---|---|---|",
    ]
    for s, rs in by.items():
        vs = (
            "–"
            if reference is None or s == reference
            else f"{ratio(rs) / ratio(by[reference]):.3f}"
        )
        lines.append(f"| {s} | {len(rs)} | {ratio(rs):.3f} | {vs} |")
    return lines


def per_day(rows: Sequence[Row]) -> dict[str, dict[int, float]]:
    """Per strategy, per scene: first-of-day oracle×."""
    firsts = first_of_day(rows)
    out: dict[str, dict[int, float]] = {}
    for s in dict.fromkeys(r.strategy for r in rows):
        mine = [r for r in firsts if r.strategy == s]
        out[s] = {
            n: ratio([r for r in mine if r.scene == n]) for n in sorted({r.scene for r in mine})
        }
    return out


#: The learning curve is read in this many consecutive blocks of days (docs/results-belief.md, v5).
CURVE_BLOCKS = 4


def _blocks(days: Sequence[int], count: int = CURVE_BLOCKS) -> list[tuple[int, ...]]:
    """``days`` in ``count`` consecutive blocks, the earlier ones a day longer when it does not
    divide (15 days: 4, 4, 4, 3)."""
    size, extra = divmod(len(days), count)
    out, at = [], 0
    for i in range(count):
        n = size + (1 if i < extra else 0)
        out.append(tuple(days[at : at + n]))
        at += n
    return [b for b in out if b]


def trend_lines(rows: Sequence[Row]) -> list[str]:
    """Whether the learning curve keeps falling: per strategy, the first search of the day ÷ the
    reference's (the table's distribution oracle, same runs and days: the days' own difficulty
    cancels) in consecutive blocks of days, and each block's paired change from the one before
    (per run, then the mean over runs, 95 % bootstrap CI over runs). A change whose CI lies above
    0 is a rise beyond noise; one whose CI holds 0 is flat within noise."""
    firsts = first_of_day(rows)
    days = sorted({r.scene for r in firsts})
    blocks = _blocks(days)
    present = _references(list(dict.fromkeys(r.strategy for r in firsts)))
    if len(blocks) < 2 or not present:
        return []
    span = [f"{b[0]}–{b[-1]}" if len(b) > 1 else str(b[0]) for b in blocks]
    lines = []
    for reference in present:
        suffix = inspection_suffix(reference)
        theirs = _runs([r for r in firsts if r.strategy == reference])

        def level(
            rs: Sequence[Row],
            key: tuple[str, str],
            block: tuple[int, ...],
            theirs: dict[tuple[str, str], list[Row]] = theirs,
        ) -> float:
            ref = [r for r in theirs.get(key, []) if r.scene in block]
            mine = [r for r in rs if r.scene in block]
            return ratio(mine) / ratio(ref) if mine and ref else math.nan

        lines += [
            f"Learning curve by blocks of days: first search ÷ {reference}'s on the same runs "
            "and days (change: paired over runs, 95 % CI):",
            "",
            "| strategy | "
            + " | ".join(f"days {d}" for d in span)
            + " | "
            + " | ".join(f"Δ {span[i]} → {span[i + 1]}" for i in range(len(span) - 1))
            + " |",
            "|---|" + "---|" * (2 * len(span) - 1),
        ]
        for s in dict.fromkeys(r.strategy for r in firsts):
            if s == reference or inspection_suffix(s) != suffix:
                continue
            runs = {
                k: v
                for k, v in _runs([r for r in firsts if r.strategy == s]).items()
                if k in theirs
            }
            if not runs:
                continue
            per_run = {k: [level(v, k, b) for b in blocks] for k, v in runs.items()}
            cells = []
            for i in range(len(blocks)):
                values = [v[i] for v in per_run.values() if not math.isnan(v[i])]
                cells.append(f"{math.fsum(values) / len(values):.3f}" if values else "–")
            for i in range(len(blocks) - 1):
                diffs = [
                    v[i + 1] - v[i]
                    for v in per_run.values()
                    if not (math.isnan(v[i]) or math.isnan(v[i + 1]))
                ]
                cells.append(_change(diffs))
            lines.append(f"| {s} | " + " | ".join(cells) + " |")
        lines.append("")
    return lines[:-1]


def _change(diffs: Sequence[float]) -> str:
    if not diffs:
        return "–"
    mean = math.fsum(diffs) / len(diffs)
    if len(diffs) < MIN_RUNS:
        return f"{mean:+.3f} (n={len(diffs)})"
    rng = random.Random(0)
    boot = sorted(
        math.fsum(rng.choice(diffs) for _ in diffs) / len(diffs) for _ in range(RESAMPLES)
    )
    low, high = boot[int(0.025 * RESAMPLES)], boot[int(0.975 * RESAMPLES) - 1]
    return f"{mean:+.3f} [{low:+.3f}, {high:+.3f}]"


def moved_lines(rows: Sequence[Row]) -> list[str]:
    """What a move costs: per strategy the pre-move level (days 6–10), the days after the move
    until the first-search ratio is back within 10 % of it, and days worse than ``ecost`` (its
    twin of the same inspection; "not run" without one, "–" for ecost itself)."""
    days = per_day(rows)
    lines = [
        "| strategy | days 6–10 | "
        + " | ".join(f"day {n}" for n in range(MOVE_SCENE, MOVE_SCENE + 5))
        + " | back within 10 % after | days worse than ecost (from the move) |",
        "|---|---|" + "---|" * 5 + "---|---|",
    ]
    for s, curve in days.items():
        twin = "ecost" + inspection_suffix(s)
        ecost = days.get(twin, {})
        before = [curve[n] for n in range(6, MOVE_SCENE) if n in curve]
        if not before:
            continue
        level = math.fsum(before) / len(before)
        after = [n for n in sorted(curve) if n >= MOVE_SCENE]
        back = next((n - MOVE_SCENE for n in after if curve[n] <= 1.1 * level), None)
        if s == twin:
            worse = "–"
        elif not ecost:
            worse = f"{twin} not run"
        else:
            worse = str(sum(1 for n in after if n in ecost and curve[n] > ecost[n]))
        cells = " | ".join(
            f"{curve[n]:.2f}" if n in curve else "–" for n in range(MOVE_SCENE, MOVE_SCENE + 5)
        )
        lines.append(
            f"| {s} | {level:.2f} | {cells} | "
            f"{'not within the run' if back is None else f'{back} day(s)'} | {worse} |"
        )
    return lines


def calibration_lines(rows: Sequence[Row]) -> list[str]:
    """The belief's forecast at each search's start, per strategy's runs: top-label ECE, mean
    Brier score, and the mean probability it gave the place the target was found at."""
    lines = [
        "| runs of | searches scored | ECE (top place) | Brier | P(found place) |",
        "|---|---|---|---|---|",
    ]
    for s in dict.fromkeys(r.strategy for r in rows):
        scored = [r for r in rows if r.strategy == s and r.belief_top_p is not None]
        if not scored:
            continue
        pairs = [(float(r.belief_top_p or 0.0), bool(r.belief_top_hit)) for r in scored]
        brier = math.fsum(float(r.belief_brier or 0.0) for r in scored) / len(scored)
        pf = math.fsum(float(r.belief_p_found or 0.0) for r in scored) / len(scored)
        lines.append(f"| {s} | {len(scored)} | {ece(pairs):.4f} | {brier:.4f} | {pf:.3f} |")
    return lines


def failure_lines(rows: Sequence[Row]) -> list[str]:
    failed = [r for r in rows if not r.success]
    if not failed:
        return ["no failures"]
    counts: dict[tuple[str, str, str], int] = {}
    for r in failed:
        counts[(r.strategy, r.home, r.target)] = counts.get((r.strategy, r.home, r.target), 0) + 1
    return [f"- {s}: {home} {target} ×{n}" for (s, home, target), n in sorted(counts.items())]


def plot_curves(rows: Sequence[Row], path: Path) -> None:
    """Panels per schedule kind: first-search oracle× per day, mean over runs with a 95 %
    bootstrap band (runs resampled), one line per strategy; PNG and SVG."""
    import matplotlib.pyplot as plt

    fig = curves_figure(rows)
    # tight: the legend below the panels is saved whole, whatever its rows.
    fig.savefig(path.with_suffix(".png"), dpi=130, bbox_inches="tight")
    fig.savefig(path.with_suffix(".svg"), bbox_inches="tight")
    plt.close(fig)


#: Width of a legend entry under the curves (the longest names, dist-oracle-global+cover, ~2.6 in).
LEGEND_INCHES_PER_ENTRY = 2.6


def curves_figure(rows: Sequence[Row]) -> Any:
    """:func:`plot_curves`' figure: one colour per strategy in every panel (each panel's own
    colour cycle gave a strategy another colour in a panel that lacks one before it, against the
    legend), and a legend in as many rows as its entries need to fit the figure's width."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kinds = sorted({kind(r) for r in rows})
    strategies = list(dict.fromkeys(r.strategy for r in first_of_day(rows)))
    palette = plt.get_cmap("tab10" if len(strategies) <= 10 else "tab20")
    colour = {s: palette(i % palette.N) for i, s in enumerate(strategies)}
    width = max(4.2 * len(kinds), 6.0)
    fig, axes = plt.subplots(1, len(kinds), figsize=(width, 3.4), squeeze=False)
    for ax, k in zip(axes[0], kinds, strict=True):
        mine = first_of_day([r for r in rows if kind(r) == k])
        for s in dict.fromkeys(r.strategy for r in mine):
            runs = _runs([r for r in mine if r.strategy == s])
            keys = sorted(runs)
            days = sorted({r.scene for r in mine})
            mean, low, high = [], [], []
            rng = random.Random(0)
            for n in days:
                per = {key: [r for r in runs[key] if r.scene == n] for key in keys}
                per = {key: v for key, v in per.items() if v}
                ks = sorted(per)
                mean.append(ratio([r for key in ks for r in per[key]]))
                boot = sorted(
                    ratio([r for key in (rng.choice(ks) for _ in ks) for r in per[key]])
                    for _ in range(500)
                )
                low.append(boot[12])
                high.append(boot[487])
            ax.plot(days, mean, label=s, linewidth=1.5, color=colour[s])
            ax.fill_between(days, low, high, alpha=0.2, color=colour[s])
        if k == "moved":
            ax.axvline(MOVE_SCENE - 0.5, color="grey", linestyle=":", linewidth=1)
        ax.set_title(f"{k} schedules")
        ax.set_xlabel("day (scene)")
        ax.set_ylabel("first search: path ÷ oracle path")
        ax.grid(alpha=0.3)
    # Every strategy of every panel once (a routine panel has references the others lack).
    legend: dict[str, Any] = {}
    for ax in axes[0]:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            legend.setdefault(label, handle)
    columns = max(1, min(len(legend), int(width // LEGEND_INCHES_PER_ENTRY)))
    legend_rows = math.ceil(len(legend) / columns)
    # Room under the panels for the legend's rows (~0.25 in each) and the axis labels.
    height = 3.4 + 0.25 * legend_rows
    fig.set_size_inches(width, height)
    bottom = (0.3 + 0.25 * legend_rows) / height
    fig.legend(list(legend.values()), list(legend), loc="lower center", ncol=columns, frameon=False)
    fig.tight_layout(rect=(0, bottom, 1, 1))
    return fig


def run_models(folder: Path) -> tuple[str, str]:
    """The detector and localisation presets a ``bench homes`` output was run with (its
    summary.json; an output written before they were recorded: ``perfect`` both)."""
    path = folder / "summary.json"
    summary = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}

    def name(key: str) -> str:
        value = summary.get(key) or {}
        return str(value.get("preset", "perfect")) if isinstance(value, dict) else str(value)

    return name("perception"), name("localisation")


def run_camera(folder: Path) -> str:
    """The search camera a ``bench homes`` output was run with (its summary.json; none recorded:
    the run predates the occluding camera, so geometric, as ``homes_command`` reads it)."""
    path = folder / "summary.json"
    summary = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    return str(summary.get("camera", "geometric"))


def select_models(
    folders: Sequence[Path], perception: str | None = None, localisation: str | None = None
) -> tuple[str, str]:
    """The one (perception, localisation) pair ``folders`` were run with; an
    :class:`ObjsearchError` naming each folder's when they differ or are not the ones asked for
    (None: any one pair)."""
    models = {folder: run_models(folder) for folder in folders}
    asked = (perception, localisation)
    wrong = [
        f"{folder} ({p}, {loc})"
        for folder, (p, loc) in models.items()
        if (perception is not None and p != perception)
        or (localisation is not None and loc != localisation)
    ]
    if wrong:
        want = ", ".join(
            f"{what} {value}"
            for what, value in zip(("perception", "localisation"), asked, strict=True)
            if value is not None
        )
        raise ObjsearchError(f"not run with {want} (perception, localisation): {'; '.join(wrong)}")
    pairs = sorted(set(models.values()))
    if len(pairs) > 1:
        named = "; ".join(f"{folder} ({p}, {loc})" for folder, (p, loc) in models.items())
        raise ObjsearchError(
            "these outputs were run with different detectors or localisations (perception, "
            f"localisation): {named}; report each apart (--perception, --localisation)"
        )
    return pairs[0] if pairs else ("perfect", "perfect")


def labelled(rows: Iterable[Row]) -> list[Row]:
    """Each row under its run's label: a run without updates (``bench homes`` runs ``wpl`` twice,
    the second with update mode none) is ``NAME/none``, ``NAME/none+cover`` with cover, so no
    table merges it with the run that updates (every table groups by ``strategy``)."""
    out = []
    for r in rows:
        if r.update_mode != "all":
            suffix = inspection_suffix(r.strategy)
            name = r.strategy.removesuffix(suffix)
            r = replace(r, strategy=f"{name}/{r.update_mode}{suffix}")
        out.append(r)
    return out


def read_outputs(folders: Sequence[Path]) -> list[Row]:
    """The searches of ``bench homes`` outputs (:func:`read_output`: a ``cover`` run's strategies
    are ``NAME+cover``), each under its run's :func:`labelled` name."""
    return labelled(r for folder in folders for r in read_output(folder))


def report(
    folders: Sequence[Path],
    out: Path | None = None,
    progress: Callable[[list[str]], Iterable[str]] | None = None,
    perfect: Sequence[Path] = (),
    baseline: tuple[str, Sequence[Path]] | None = None,
    data: Sequence[Path] = (),
) -> str:
    """The belief's figures for ``folders``, per schedule kind (``progress`` wraps the kinds as
    they are reported: the CLI's progress line); then the perception protocol's measures of their
    ``habit`` runs (experiments/report_protocol.py), ÷ the same strategies' runs in ``perfect``
    (outputs of ``bench homes --perception perfect``) and in ``baseline`` (label, outputs of runs
    that differ in one factor) when given; and, for the outputs run with ``--new-map-day``, the
    first search in the new map against ecost's (experiments/report_newmap.py), per day. Each
    output's homes are read from the data folder it was run on, else one of ``data``, else the
    process's (experiments/report_data.py)."""
    from objsearch.experiments.report_homes import failure_cause
    from objsearch.experiments.report_newmap import new_map_day, new_map_lines
    from objsearch.experiments.report_protocol import protocol_lines

    per_folder = {folder: read_outputs([folder]) for folder in folders}
    rows = [r for rs in per_folder.values() for r in rs]
    if not rows:
        return "no searches in these outputs"
    theirs = {f: read_outputs([f]) for f in [*perfect, *(baseline[1] if baseline else ())]}
    home_data = home_folders(
        {f: sorted({r.home for r in rs}) for f, rs in [*per_folder.items(), *theirs.items()]},
        data,
    )

    def cause(r: Row) -> str:
        return failure_cause(r, camera, home_data[r.home])

    camera = run_camera(folders[0])
    homes = sorted({r.home for r in rows})
    seeds = sorted({r.seed for r in rows})
    lines = [
        f"{len(rows)} searches; homes ({len(homes)}): {', '.join(homes)}; seeds {seeds}; "
        f"intervals: 95 % bootstrap over runs (home × schedule), shown from {MIN_RUNS} runs",
    ]
    kinds = sorted({kind(r) for r in rows})
    for k in progress(kinds) if progress else kinds:
        mine = [r for r in rows if kind(r) == k]
        after = after_scene(k)
        lines += ["", f"### {k} schedules", "", *ratio_table(mine, after), ""]
        names = {r.strategy for r in mine}
        suffixes = sorted({inspection_suffix(n) for n in names})
        lines += paired_lines(
            mine,
            [
                *((a + suffix, b + suffix) for suffix in suffixes for a, b in PAIRS),
                *((n + COVER_SUFFIX, n) for n in sorted(names) if n + COVER_SUFFIX in names),
            ],
            after,
        )
        if k in ROUTINE_KINDS:
            lines += ["", *slot_lines(mine, after), "", *first_of_scene_lines(mine, after)]
        if k == "moved":
            lines += ["", *moved_lines(mine)]
        if k == "habit":
            lines += ["", *usual_place_lines(mine, data=home_data)]
        if k in ("habit", "stats"):
            lines += ["", *trend_lines(mine)]
        lines += ["", "Calibration of the belief's forecast at the start of each search:", ""]
        lines += calibration_lines(mine)
        lines += ["", "Failures (strategy: home target ×searches):", *failure_lines(mine)]
    measures = protocol_lines(
        rows,
        [r for f in perfect for r in theirs[f]],
        cause,
        baseline=(baseline[0], [r for f in baseline[1] for r in theirs[f]]) if baseline else None,
    )
    if measures:
        lines += ["", *measures]
    days: dict[int, list[Row]] = {}
    for folder, rs in per_folder.items():
        day = new_map_day(folder)
        if day is not None:
            days.setdefault(day, []).extend(rs)
    for day, rs in sorted(days.items()):
        lines += ["", *new_map_lines(rs, day)]
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        plot_curves(rows, out / "belief_curves")
        lines += ["", f"Learning curves with CI bands: {out / 'belief_curves.png'} (and .svg)"]
    return "\n".join(lines)


def main_summary(folders: Sequence[Path]) -> dict[str, Any]:
    """The per-day curves as JSON (for a notebook or a plot of one's own)."""
    rows = read_outputs(folders)
    return {k: per_day([r for r in rows if kind(r) == k]) for k in sorted({kind(r) for r in rows})}
