"""The held-out homes sections of docs/results.md (``bench report --evaluation``, ``--heldout``): issue
16's figures recomputed from a ``bench homes`` output's rows, so every number is traceable to
the searches it summarises.

Per strategy: path to discovery (the paper's metric) and the full path; Σpath/Σoracle of all
searches and of the *first search of the day*, overall and after scene :data:`AFTER`; success;
the exact excess decomposition; learning curves and per-home error bars (PNG, SVG, PDF); paired differences against ``wpl``
(a 95 % CI only over enough runs, experiments/stats.py); how
often updates made a strategy longer than its no-update twin; every failure with its cause; and
the strategy table again per home family and per schedule kind.
"""

from __future__ import annotations

import math
import statistics
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from objsearch.agent.datapaths import data_key
from objsearch.agent.geometry import Pose, heading
from objsearch.agent.session import load_context
from objsearch.agent.stops import cover_views, static_pitch, stop_statics
from objsearch.experiments.homes import family, schedule_kind
from objsearch.experiments.learning import (
    excess_breakdown,
    first_of_day,
    key,
    paired_differences,
    plot_curves,
    ratio,
    run_of,
)
from objsearch.experiments.metrics import spl_term
from objsearch.experiments.paper import discovery
from objsearch.experiments.plots import pyplot, save_figure
from objsearch.experiments.runner import Row, inspection_suffix
from objsearch.experiments.stats import CI, MIN_RUNS, method_note, spread
from objsearch.experiments.strategies import COVER_SUFFIX
from objsearch.sim.longterm import scenes_of
from objsearch.sim.placements import Placement
from objsearch.sim.world import DEFAULT_CAMERA, first_sighting, search_camera

#: "After scene 10": the issue's targets are read on the searches of later scenes.
AFTER = 10
#: Issue 16: updates may make a strategy longer than no update on at most 1 run in 20.
UPDATE_REGRESSION_TARGET = 1 / 20


def _m(v: float) -> str:
    return "–" if math.isnan(v) else f"{v:.2f}"


def _by_key(rows: Sequence[Row]) -> dict[str, list[Row]]:
    out: dict[str, list[Row]] = {}
    for r in rows:
        out.setdefault(key(r), []).append(r)
    return out


def strategy_table(rows: Sequence[Row]) -> list[str]:
    """One line per strategy (``/none``: its no-update twin)."""
    lines = [
        f"| strategy | path to discovery m | full path m | oracle× all | oracle× first of day "
        f"| all× after scene {AFTER} | first× after scene {AFTER} | success | SPL | searches |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for k, rs in _by_key(rows).items():
        late = [r for r in rs if r.scene > AFTER]
        lines.append(
            f"| {k} | {statistics.fmean(discovery(r) for r in rs):.2f} "
            f"| {statistics.fmean(r.path_length for r in rs):.2f} | {_m(ratio(rs))} "
            f"| {_m(ratio(first_of_day(rs)))} | {_m(ratio(late)) if late else '–'} "
            f"| {_m(ratio(first_of_day(late))) if late else '–'} "
            f"| {100 * sum(r.success for r in rs) / len(rs):.2f} % "
            f"| {statistics.fmean(spl_term(r) for r in rs):.3f} | {len(rs)} |"
        )
    return lines


def excess_table(rows: Sequence[Row]) -> list[str]:
    lines = [
        "| strategy | full path m | oracle m | excess m | wrong rooms m | of which start room m "
        "| right room m | approach m | wrong rooms share of the path |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for k, rs in _by_key(rows).items():
        e = excess_breakdown(rs)
        if not e.get("n"):
            continue
        share = e["wrong_rooms"] / e["path"] if e["path"] > 0 else math.nan
        lines.append(
            f"| {k} | {e['path']:.2f} | {e['oracle']:.2f} | {e['excess']:.2f} "
            f"| {e['wrong_rooms']:.2f} | {e['start_room']:.2f} | {e['right_room']:.2f} "
            f"| {e['approach']:.2f} | {'–' if math.isnan(share) else f'{100 * share:.0f} %'} |"
        )
    return lines


def paired_table(rows: Sequence[Row]) -> list[str]:
    paired = paired_differences(rows, metric=discovery)
    if not paired:
        ran = ", ".join(dict.fromkeys(key(r) for r in rows))
        return [
            f"(no strategy shares a run with wpl of its own inspection to pair with; these "
            f"outputs hold {ran}: add wpl to bench homes --strategies)"
        ]
    lines = [
        f"| strategy | Δ path to discovery vs wpl (wpl+cover for a cover run) m | {CI} (or the "
        f"range, under {MIN_RUNS} runs) | runs |",
        "|---|---|---|---|",
    ]
    for k, d in paired.items():
        lines.append(f"| {k} | {d.mean:+.2f} | {d.text()} | {d.n} |")
    return lines


def update_regressions(rows: Sequence[Row]) -> dict[str, tuple[int, int]]:
    """Per strategy with a no-update twin: (runs where its mean path to discovery is longer than
    the twin's, runs compared), over (home, schedule-with-seed) runs."""
    means: dict[tuple[str, str, str], list[float]] = {}
    for r in rows:
        means.setdefault((key(r), r.home, r.placements), []).append(discovery(r))
    run_mean = {k: statistics.fmean(v) for k, v in means.items()}
    out: dict[str, tuple[int, int]] = {}
    for (k, home, spec), own in sorted(run_mean.items()):
        twin = run_mean.get((f"{k}/none", home, spec))
        if "/" in k or twin is None:
            continue
        longer, runs = out.get(k, (0, 0))
        out[k] = (longer + (own > twin + 1e-9), runs + 1)
    return out


def regression_lines(rows: Sequence[Row]) -> list[str]:
    found = update_regressions(rows)
    if not found:
        return ["(no strategy ran with its no-update twin; bench homes adds `wpl/none` with wpl)"]
    lines = []
    for k, (longer, runs) in found.items():
        verdict = "met" if longer <= UPDATE_REGRESSION_TARGET * runs else "NOT met"
        lines.append(
            f"- {k}: updates made it longer than {k}/none in **{longer} of {runs}** "
            f"(home, schedule, seed) runs; target at most 1 in 20 ({verdict})"
        )
    return lines


@dataclass(frozen=True, slots=True)
class Failure:
    row: Row
    cause: str


@cache
def _scene_placements(
    home: str, spec: str, upto: int, folder: Path
) -> dict[int, dict[str, Placement]]:
    return {s: dict(p) for s, p in scenes_of(home, spec, upto=upto, data=folder).items()}


def failure_cause(row: Row, camera: str = DEFAULT_CAMERA, data: Path | None = None) -> str:
    """Why a search failed, from what can be told without its log (``bench homes`` keeps none):
    where the target was that scene and what the run's ``camera`` shows of it, with everything
    placed in its room in the way — from any viewpoint of the room and from the one viewpoint
    the agent inspects its static from (N_s, paper §4). The home is read from the data folder
    ``data`` (the one the row was run on; None: ``datapaths.data_dir()``)."""
    cover = inspection_suffix(row.strategy) == COVER_SUFFIX
    folder = data_key(data)
    return _cause(row.home, row.placements, row.scene, row.target, camera, cover, folder)


@cache
def _cause(
    home: str,
    placements: str,
    scene: int,
    target: str,
    camera_name: str,
    cover: bool,
    folder: Path,
) -> str:
    everything = _scene_placements(home, placements, scene, folder)[scene]
    placed = [p for p in everything.values() if p.cls == target]
    if not placed:
        return "not placed in this scene"
    ctx = load_context(home, folder)
    camera = search_camera(camera_name)
    oc = ctx.vocabulary.classes.get(target)
    threshold = oc.min_mask_area_px if oc is not None else math.inf
    p = placed[0]
    room = [q for q in everything.values() if q.room == p.room]
    anywhere = first_sighting(camera, ctx.home, p, room, ctx.navmap.viewpoints(p.room), threshold)
    if anywhere.viewpoint is None:
        return (
            f"never detectable ({camera_name} camera): its best view from any viewpoint of "
            f"{p.room} is {anywhere.mask_px:.0f} px < {threshold:g} px"
        )
    stops = [s.viewpoint for s in ctx.semmap.in_room(p.room) if s.id == p.support]
    at_stop = first_sighting(camera, ctx.home, p, room, stops, threshold)
    if at_stop.viewpoint is None:
        v = anywhere.viewpoint
        elsewhere = (
            f"detectable from elsewhere in {p.room} ({anywhere.mask_px:.0f} px from "
            f"({v.x:g}, {v.y:g})) but not from the viewpoint its static is inspected from "
            f"({at_stop.mask_px:.0f} px < {threshold:g} px; one viewpoint per static, paper §4)"
        )
        if not cover:
            return elsewhere
        key = next(s for s in ctx.semmap.in_room(p.room) if s.id == p.support)
        views = cover_views(ctx.navmap, key.viewpoint, stop_statics(ctx.semmap, p.room, key))
        best = 0.0
        for view in views:
            pose = Pose(view.viewpoint.x, view.viewpoint.y, heading(view.viewpoint, view.stretch))
            pitch = static_pitch(view.viewpoint, view.static)
            seen = camera.detections(ctx.home, p.room, pose, pitch, room, (p,), None)
            best = max([best, *(d.mask_area for d in seen)])
        if best >= threshold:
            return f"{elsewhere}; a stretch inspection cover looks at shows {best:.0f} px"
        return (
            f"{elsewhere}, nor from the {len(views)} stretches inspection cover looks at "
            f"({best:.0f} px at best)"
        )
    if p.inside:
        return f"inside {p.support} in {p.room}: seen only if opened"
    return (
        f"detectable from its static's viewpoint ({at_stop.mask_px:.0f} px), not detected: the search "
        "ended without that view"
    )


#: The cause of a failure in a run that recorded no camera: it predates the search camera choice
#: and the schedules' visibility and overlap checks, so today's draw of its schedule is not the
#: draw it searched, and a cause computed from today's would name the wrong placement.
UNKNOWN_CAUSE = (
    "not computed: the run predates the schedules' visibility checks (no camera recorded), so "
    "its scenes cannot be drawn again"
)


def failures(rows: Sequence[Row], camera: str | None = DEFAULT_CAMERA) -> list[Failure]:
    """Failed searches with their causes (``camera`` None: a run that recorded none)."""
    return [
        Failure(r, UNKNOWN_CAUSE if camera is None else failure_cause(r, camera))
        for r in rows
        if not r.success
    ]


def failure_lines(rows: Sequence[Row], camera: str | None = DEFAULT_CAMERA) -> list[str]:
    """Success, and every failure named with its cause: one line per (home, schedule, scene,
    target) — the searches that failed there, by strategy — since a cause belongs to a
    placement, and a protocol-scale run fails the same placement from many starts."""
    failed = failures(rows, camera)
    n = len(rows)
    lines = [
        f"Success {100 * (n - len(failed)) / n:.2f} % ({n - len(failed)} of {n} searches); "
        + ("no failures." if not failed else f"{len(failed)} failures, each with its cause:")
    ]
    if failed:
        groups: dict[tuple[str, str, int, str], list[Failure]] = {}
        for f in failed:
            groups.setdefault((f.row.home, f.row.placements, f.row.scene, f.row.target), []).append(
                f
            )
        lines += [
            "",
            "| home | schedule | scene | target | failed searches (strategy × start) | cause |",
            "|---|---|---|---|---|---|",
        ]
        for (home, sched, scene, target), fs in sorted(groups.items()):
            by = Counter(key(f.row) for f in fs)
            who = ", ".join(f"{k} ×{c}" for k, c in sorted(by.items()))
            lines.append(f"| {home} | {sched} | {scene} | {target} | {who} | {fs[0].cause} |")
    return lines


def plot_homes(rows: Sequence[Row], path: Path) -> list[Path]:
    """Mean path to discovery per home and strategy: the mean over that home's runs with an error
    bar (95 % CI with enough runs, else the runs' range: experiments/stats.py)."""
    plt = pyplot()
    homes = sorted({r.home for r in rows})
    keys = list(_by_key(rows))
    runs: dict[tuple[str, str], dict[tuple[str, str, int], list[float]]] = {}
    for r in rows:
        runs.setdefault((r.home, key(r)), {}).setdefault(run_of(r), []).append(discovery(r))
    fig, ax = plt.subplots(figsize=(max(6.5, len(homes) * 0.5 + 1.5), 3.6))
    width = 0.8 / len(keys)
    kinds: set[str] = set()
    for i, k in enumerate(keys):
        xs, means, lows, highs = [], [], [], []
        for x, h in enumerate(homes):
            per_run = runs.get((h, k))
            if not per_run:
                continue
            d = spread([statistics.fmean(v) for v in per_run.values()])
            kinds.add(d.kind)
            xs.append(x - 0.4 + width * (i + 0.5))
            means.append(d.mean)
            lows.append(d.mean - d.low)
            highs.append(d.high - d.mean)
        ax.bar(xs, means, width, label=k, color=f"C{i % 10}")
        ax.errorbar(xs, means, yerr=[lows, highs], fmt="none", ecolor="k", elinewidth=0.7,
                    capsize=1.5)  # fmt: skip
    ax.set_xticks(range(len(homes)))
    ax.set_xticklabels(homes, rotation=60, ha="right")
    ax.set_xlabel("home")
    ax.set_ylabel("mean path to discovery (m)")
    ax.set_title(
        "Per home and strategy; error bars: " + " or ".join(sorted(kinds))
        + f" over runs (CI only with ≥ {MIN_RUNS} runs)"
    )  # fmt: skip
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False, title="strategy")
    return save_figure(fig, path)


def homes_section(
    title: str,
    summary: dict[str, Any],
    rows: Sequence[Row],
    img: Path,
    img_link: str,
    plot_prefix: str,
) -> str:
    """A whole section: ``img`` is where the PNGs go, ``img_link`` how the page refers to it."""
    homes = sorted({r.home for r in rows})
    kinds = sorted({schedule_kind(r.placements) for r in rows})
    seeds = sorted({r.seed for r in rows})
    plots = plot_curves(rows, img, prefix=plot_prefix)
    plot_homes(rows, img / f"{plot_prefix}_per_home.png")
    plots.append(img / f"{plot_prefix}_per_home.png")
    out = [
        f"## {title}",
        "",
        f"Commands ({summary['searches']} searches, {summary['elapsed_s']} s with "
        f"{summary['workers']} process(es)):",
        "",
        "```sh",
        *summary.get("data_build", ()),
        *summary.get("commands", [summary.get("command", "objsearch bench homes")]),
        "```",
        "",
        f"Homes ({len(homes)}): {', '.join(homes)}. Schedules: {', '.join(kinds)}, seeds "
        f"{seeds}. Prior: `{summary.get('prior', 'vg-cooccurrence')}` (Visual Genome only; no "
        "AI2-THOR statistics) for every strategy, which then learns from its own searches only; "
        "`dist-oracle` alone reads the schedule's own placement distribution (a reference).",
        "",
        "### Per strategy (all homes, all schedules)",
        "oracle× is Σ full path / Σ oracle path; the first search of the day is the first for "
        "each target in each scene; SPL (Anderson et al. 2018) is the mean of "
        "success × oracle path ÷ max(path, oracle path). " + _oracle_note(summary),
        "",
        *strategy_table(rows),
        "",
        "### Where the path goes (per successful search)",
        "Each leg is charged to the room it ends in (experiments/decompose.py); the parts — "
        "wrong rooms, the right room before the final approach, the approach — sum to the full "
        "path and are never negative. The oracle's walk is shown beside them, not subtracted "
        "from a part: it crosses other rooms on its way, so a part net of it could be negative "
        "and a share of the excess could pass 100 %.",
        "",
        *excess_table(rows),
        "",
        "### Learning curves",
        "A panel per strategy: the mean over runs of each run's Σ path / Σ oracle per scene, its "
        "band over runs (as below), and wpl's curve in grey for reference; error bars per home "
        "likewise.",
        "",
        *(f"![{p.stem}]({img_link}/{p.name})" for p in plots),
        "",
        "### Against the paper's WPL: paired differences over (home, schedule, seed) runs",
        method_note(),
        "",
        *paired_table(rows),
        "",
        "### Updates against no update",
        *regression_lines(rows),
        "",
        "### Success and failures",
        *failure_lines(rows, summary.get("camera")),
    ]
    for label, group in (("home family", _family), ("schedule kind", _kind)):
        for name in sorted({group(r) for r in rows}):
            out += ["", f"### {label.capitalize()}: {name}"]
            out += strategy_table([r for r in rows if group(r) == name])
    return "\n".join(out) + "\n"


def _oracle_note(summary: dict[str, Any]) -> str:
    """What the oracle walked in this run: a run that recorded no camera predates the oracle
    measured like a search's full path (sim/world.py ``oracle_length``)."""
    if summary.get("camera") is None:
        return (
            "This run recorded no camera: its oracle walked straight to the viewpoint nearest the "
            "target (whether or not that viewpoint sees it)."
        )
    return (
        f"The oracle walks to the nearest viewpoint from which the {summary['camera']} camera "
        "detects the target, then on to the viewpoint nearest it, as a search's full path does."
    )


def _family(r: Row) -> str:
    return family(r.home)


def _kind(r: Row) -> str:
    return schedule_kind(r.placements)
