"""``objsearch bench sensitivity``: how the search degrades as the detector gets worse (issue 45).

A grid of detectors — the recall multiplied by each ``recall_scale``, each ``fp_per_image`` false
positives per view — over a base preset (``perfect`` by default, so the grid's recall is the
recall itself: 1.0 → 0.5). Each grid cell is one ``bench homes`` run (:func:`homes_jobs`,
:func:`run_jobs`, :func:`homes_summary`: the same searches ``bench homes`` makes), with the
strategies and, beside them, the reference that sees with the same detector
(``dist-oracle-global`` with each strategy's inspection, :func:`reference_of`) — also in the
perfect cell, so path ÷ reference is measured the same way in every cell.

Per cell and strategy: success (a "found" on a false positive or a confusion is a failure),
false found, mean path, path ÷ reference on the same searches, and the calibration of ``where``
(:mod:`objsearch.experiments.calibration`: top-label ECE in 10 equal-width bins and the mean
Brier score of the belief's forecast at the start of each search that found its target).
Writes the table as text, JSON and a Markdown block, a plot with one panel per measure, and each
cell's searches (``cells/<cell>/homes_trials.parquet``, readable by ``bench belief``).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from objsearch.experiments.calibration import BINS, ece
from objsearch.experiments.homes import homes_jobs, homes_summary, reference_of
from objsearch.experiments.runner import Job, Row, command_line, run_jobs, write_rows
from objsearch.experiments.strategies import full_strategy_name, split_strategy
from objsearch.sim.world import DEFAULT_CAMERA

#: The grid of issue 45 and docs/protocol-perception.md ("Sensitivity").
RECALL_SCALES = (1.0, 0.85, 0.7, 0.5)
FP_PER_IMAGE = (0.0, 0.25, 0.5, 1.0)
#: The default and the paper's strategy, both inspecting as the default does.
STRATEGIES = ("global-belief+cover", "wpl+cover")
#: What the command writes into --out (an earlier run's files are replaced).
OUTPUTS = (
    "sensitivity.json",
    "sensitivity.txt",
    "sensitivity.md",
    "sensitivity.png",
    "sensitivity.svg",
    "sensitivity.pdf",
    "cells",
)
#: The measures of the table and the plot's panels: key, title, and how a value is printed.
MEASURES: tuple[tuple[str, str, str], ...] = (
    ("success_rate", "success", "{:.1%}"),
    ("reference_ratio", "path ÷ reference", "{:.2f}"),
    ("ece", f"ECE of where ({BINS} bins)", "{:.3f}"),
    ("brier", "Brier of where", "{:.3f}"),
)


@dataclass(frozen=True, slots=True)
class Cell:
    """One detector of the grid: the base preset's recall times ``recall_scale``, and
    ``fp_per_image`` false positives per view."""

    recall_scale: float
    fp_per_image: float

    @property
    def name(self) -> str:
        return f"recall-{self.recall_scale:g}_fp-{self.fp_per_image:g}"


def grid(recall_scales: Sequence[float], fp_per_image: Sequence[float]) -> list[Cell]:
    """Every (recall scale, false positives) pair, each value once, in the order given."""
    return [Cell(r, f) for r in dict.fromkeys(recall_scales) for f in dict.fromkeys(fp_per_image)]


def cell_perception(base: str, cell: Cell, relook: str | None = None) -> dict[str, Any] | None:
    """The run spec's ``params.perception`` of a cell: the base preset with the cell's recall
    scale and false positives, and ``relook`` (None: the preset's; ``perfect``'s is off, even
    where the cell's recall makes it miss); None when that is a perfect detector (the run of
    old)."""
    from objsearch.agent.detector_model import preset

    model = preset(
        base, relook=relook, recall_scale=cell.recall_scale, fp_per_image=cell.fp_per_image
    )
    return None if model.perfect else model.params()


def _preset_relook(base: str) -> str:
    from objsearch.agent.detector_model import preset

    return preset(base).relook


def cell_jobs(
    cell: Cell,
    *,
    base: str,
    homes: Sequence[str],
    strategies: Sequence[str],
    seeds: int,
    scenes: int | None,
    schedules: Sequence[str],
    starts_per_search: int | None,
    camera: str = DEFAULT_CAMERA,
    relook: str | None = None,
) -> list[Job]:
    """``bench homes``' jobs for one cell: the strategies and their references, all learning
    (``bench homes``' extra ``wpl/none`` runs are not part of the grid)."""
    perception = cell_perception(base, cell, relook)
    with_refs = list(dict.fromkeys([*strategies, *map(reference_of, strategies)]))
    jobs = homes_jobs(
        homes,
        with_refs,
        seeds,
        scenes=scenes,
        schedules=schedules,
        starts_per_search=starts_per_search,
        camera=camera,
        perception=json.dumps(perception, sort_keys=True) if perception else None,
    )
    return [j for j in jobs if j.update_mode == "all"]


def measures(rows: Sequence[Row]) -> dict[str, dict[str, Any]]:
    """Per strategy of one cell's searches: searches, success, false found, mean path, path ÷
    the reference on the same searches (None for the reference itself), and ``where``'s ECE and
    Brier over the searches that found their target."""
    summary = homes_summary(rows)
    out: dict[str, dict[str, Any]] = {}
    for name, s in summary["overall"].items():
        mine = [r for r in rows if r.strategy == name and r.update_mode == "all"]
        scored = [r for r in mine if r.belief_top_p is not None]
        pairs = [(float(r.belief_top_p or 0.0), bool(r.belief_top_hit)) for r in scored]
        out[name] = {
            "searches": s["n"],
            "success_rate": s["success_rate"],
            "false_found_rate": s["false_found_rate"],
            "mean_path_length": s["mean_path_length"],
            "reference": s.get("reference"),
            "reference_ratio": s.get("reference_ratio"),
            "scored": len(scored),
            "ece": ece(pairs) if pairs else None,
            "brier": math.fsum(float(r.belief_brier or 0.0) for r in scored) / len(scored)
            if scored
            else None,
        }
    return out


def cell_line(
    index: int, total: int, cell: Cell, result: dict[str, Any], strategies: Sequence[str]
) -> str:
    """The progress line of a finished cell."""
    parts = []
    for name in strategies:
        m = result["strategies"].get(name)
        if m is None:
            continue
        ratio = m["reference_ratio"]
        parts.append(
            f"{name} success {m['success_rate']:.1%} ÷ ref "
            f"{'–' if ratio is None else f'{ratio:.2f}'} ECE {_fmt(m['ece'], '{:.3f}')}"
        )
    return (
        f"bench sensitivity: cell {index}/{total} recall ×{cell.recall_scale:g}, "
        f"{cell.fp_per_image:g} FP/image: {result['searches']} searches in "
        f"{result['elapsed_s']:.0f} s; " + "; ".join(parts)
    )


def run_sensitivity(
    out: Path,
    *,
    homes: Sequence[str],
    seeds: int = 1,
    scenes: int | None = None,
    schedules: Sequence[str] = ("habit",),
    starts_per_search: int | None = None,
    strategies: Sequence[str] = STRATEGIES,
    recall_scales: Sequence[float] = RECALL_SCALES,
    fp_per_image: Sequence[float] = FP_PER_IMAGE,
    base: str = "perfect",
    relook: str | None = None,
    inspection: str = "single",
    camera: str = DEFAULT_CAMERA,
    workers: int = 1,
    bar: bool = False,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run every cell of the grid (one ``bench homes`` run each) and write the table, its JSON,
    its Markdown block, the plot and each cell's searches under ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    # ``--inspection cover`` is every strategy named NAME+cover, as in bench homes.
    strategies = list(
        dict.fromkeys(
            full_strategy_name(registered.name, "cover" if inspection == "cover" else own)
            for registered, own in map(split_strategy, strategies)
        )
    )
    cells = grid(recall_scales, fp_per_image)
    started = time.perf_counter()
    results = []
    for i, cell in enumerate(cells, 1):
        jobs = cell_jobs(
            cell,
            base=base,
            homes=homes,
            strategies=strategies,
            seeds=seeds,
            scenes=scenes,
            schedules=schedules,
            starts_per_search=starts_per_search,
            camera=camera,
            relook=relook,
        )
        t0 = time.perf_counter()
        rows = run_jobs(jobs, workers=workers, progress=bar, label=f"bench sensitivity {cell.name}")
        folder = out / "cells" / cell.name
        folder.mkdir(parents=True, exist_ok=True)
        write_rows(rows, folder, "homes_trials")
        result = {
            "recall_scale": cell.recall_scale,
            "fp_per_image": cell.fp_per_image,
            "perception": cell_perception(base, cell, relook) or {"preset": "perfect"},
            "searches": len(rows),
            "elapsed_s": round(time.perf_counter() - t0, 1),
            "strategies": measures(rows),
        }
        results.append(result)
        if progress is not None:
            progress(cell_line(i, len(cells), cell, result, strategies))
    command = command_line(
        "objsearch bench sensitivity",
        {
            "out": out,
            "homes": list(homes),
            "schedules": list(schedules),
            "seeds": seeds,
            "scenes_per_schedule": scenes,
            "starts_per_scene": starts_per_search,
            "strategies": strategies,
            "recall_scales": [f"{r:g}" for r in dict.fromkeys(recall_scales)],
            "fp_rates": [f"{f:g}" for f in dict.fromkeys(fp_per_image)],
            "perception": None if base == "perfect" else base,
            "relook": relook,
            "camera": None if camera == DEFAULT_CAMERA else camera,
            "workers": workers,
        },
    )
    summary: dict[str, Any] = {
        "command": command,
        "homes": list(homes),
        "seeds": list(range(seeds)),
        "schedules": list(schedules),
        "scenes": scenes or "each kind's own",
        "starts_per_search": starts_per_search or "every start",
        "camera": camera,
        "base_perception": base,
        "relook": relook or _preset_relook(base),
        "strategies": strategies,
        "references": list(dict.fromkeys(map(reference_of, strategies))),
        "recall_scales": list(dict.fromkeys(recall_scales)),
        "fp_per_image": list(dict.fromkeys(fp_per_image)),
        "ece_bins": BINS,
        "elapsed_s": round(time.perf_counter() - started, 1),
        "searches": sum(r["searches"] for r in results),
        "cells": results,
    }
    _write_outputs(summary, out)
    return summary


def _write_outputs(summary: dict[str, Any], out: Path) -> None:
    """The plot (its file names into ``summary``), the JSON, the text table and its Markdown."""
    summary["plot"] = [p.name for p in plot(summary, out / "sensitivity.png")]
    (out / "sensitivity.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    (out / "sensitivity.txt").write_text(render(summary) + "\n", encoding="utf-8")
    (out / "sensitivity.md").write_text(markdown(summary) + "\n", encoding="utf-8")


def _fmt(value: float | None, form: str) -> str:
    return (
        "–"
        if value is None or (isinstance(value, float) and math.isnan(value))
        else form.format(value)
    )


def _table_rows(summary: dict[str, Any]) -> list[list[str]]:
    rows = []
    for cell in summary["cells"]:
        for name in summary["strategies"]:
            m = cell["strategies"].get(name)
            if m is None:
                continue
            rows.append(
                [
                    f"{cell['recall_scale']:g}",
                    f"{cell['fp_per_image']:g}",
                    name,
                    str(m["searches"]),
                    _fmt(m["success_rate"], "{:.1%}"),
                    _fmt(m["false_found_rate"], "{:.2%}"),
                    _fmt(m["mean_path_length"], "{:.2f}"),
                    _fmt(m["reference_ratio"], "{:.2f}"),
                    _fmt(m["ece"], "{:.3f}"),
                    _fmt(m["brier"], "{:.3f}"),
                ]
            )
    return rows


HEADER = (
    "recall ×",
    "FP/image",
    "strategy",
    "searches",
    "success",
    "false found",
    "path m",
    "÷ ref",
    "ECE",
    "Brier",
)


def _preamble(summary: dict[str, Any]) -> str:
    base = summary["base_perception"]
    return (
        f"{len(summary['homes'])} home(s) ({', '.join(summary['homes'])}) × "
        f"{len(summary['seeds'])} seed(s), {', '.join(summary['schedules'])} schedules, "
        f"{summary['scenes']} scenes, {summary['starts_per_search']} start(s) per scene; "
        f"detector: the {base} preset's recall × the row's scale, the row's false positives per "
        f"image, relook {summary.get('relook', 'off')}; ÷ ref: path ÷ {', '.join(summary['references'])} (seeing with the same "
        f"detector) on the same searches; ECE ({summary['ece_bins']} bins, top place) and Brier "
        "of where's forecast at the start of each search that found its target"
    )


def render(summary: dict[str, Any]) -> str:
    """The table as text."""
    rows = _table_rows(summary)
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(HEADER)]

    def line(cells: Sequence[str]) -> str:
        return "  ".join(
            c.ljust(w) if i == 2 else c.rjust(w)
            for i, (c, w) in enumerate(zip(cells, widths, strict=True))
        )

    return "\n".join([_preamble(summary), line(HEADER), *map(line, rows)])


def markdown(summary: dict[str, Any]) -> str:
    """The table as a Markdown block a page can embed, with the command that made it."""
    lines = [
        f"```\n{summary['command']}\n```",
        "",
        _preamble(summary) + ".",
        "",
        "| " + " | ".join(HEADER) + " |",
        "|" + "---|" * len(HEADER),
    ]
    lines += ["| " + " | ".join(r) + " |" for r in _table_rows(summary)]
    return "\n".join(lines)


def plot(summary: dict[str, Any], png: Path) -> list[Path]:
    """One panel per measure against false positives per image: a colour per recall scale, a
    line style per strategy (PNG, SVG and PDF)."""
    from objsearch.experiments.plots import pyplot, save_figure

    plt = pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(7.6, 5.6), sharex=True, squeeze=False)
    styles = ("-o", "--s", ":^", "-.v")
    scales = summary["recall_scales"]
    for ax, (key, title, _) in zip(axes.flat, MEASURES, strict=True):
        for si, name in enumerate(summary["strategies"]):
            for ci, scale in enumerate(scales):
                points = [
                    (c["fp_per_image"], c["strategies"][name][key])
                    for c in summary["cells"]
                    if c["recall_scale"] == scale
                    and name in c["strategies"]
                    and c["strategies"][name][key] is not None
                    and not math.isnan(c["strategies"][name][key])
                ]
                points.sort()
                if not points:
                    continue
                ax.plot(
                    [x for x, _ in points],
                    [y for _, y in points],
                    styles[si % len(styles)],
                    color=f"C{ci}",
                    lw=1.3,
                    ms=3.5,
                    label=f"{name}, recall ×{scale:g}",
                )
        ax.set_title(title)
        if key == "success_rate":
            # A rate: never drawn above 100 %.
            low = min((y for line in ax.get_lines() for y in line.get_ydata()), default=0.95)
            ax.set_ylim(max(0.0, min(float(low) - 0.01, 0.95)), 1.005)
            ax.yaxis.set_major_formatter(plt.FuncFormatter(lambda v, _: f"{v:.0%}"))
    for ax in axes[-1]:
        ax.set_xlabel("false positives per image")
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, frameon=False)
    fig.suptitle(
        f"{', '.join(summary['homes'])}; {len(summary['seeds'])} seed(s); "
        f"{summary['base_perception']} detector's recall × scale",
        fontsize=9,
    )
    rows = math.ceil(len(labels) / 2)
    fig.tight_layout(rect=(0, 0.035 * rows + 0.02, 1, 0.96))
    return save_figure(fig, png)
