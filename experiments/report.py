"""``objsearch bench report``: docs/results.md and its plots, generated from bench outputs.

Each section is rendered by the module that owns its figures (``report_paper``, ``report_homes``,
``table1_sets``); this module only loads the inputs and puts the page together. An optional input
that was not given leaves its section out, with a line saying which command produces it.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from objsearch.agent.errors import ObjsearchError
from objsearch.agent.session import DEFAULT_PRIOR
from objsearch.experiments.homes import data_build_commands, homes_command, homes_summary
from objsearch.experiments.report_homes import homes_section
from objsearch.experiments.report_paper import cameras_section, paper_section
from objsearch.experiments.runner import Row, read_output
from objsearch.experiments.table1_sets import render as render_table1


@dataclass(frozen=True, slots=True)
class ReportInputs:
    """The bench output folders a report is made from (None: that section is left out)."""

    paper: Path | None = None
    homes: tuple[Path, ...] = ()  # none: that section is left out
    table1: tuple[Path, ...] | None = None  # one bench table1 run per reading of Eq. 2
    heldout: tuple[Path, ...] | None = None
    paper_geometric: Path | None = None


def load_summary(folder: Path, command: str) -> dict[str, Any]:
    path = folder / "summary.json"
    if not path.is_file():
        raise ObjsearchError(f"no bench summary at {path}; run `objsearch {command}` first")
    doc: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return doc


def load_homes(folders: Sequence[Path]) -> tuple[dict[str, Any], list[Row]]:
    """The rows of one or more ``bench homes`` outputs as one run: a summary recomputed over all
    rows, with every folder's command (one per schedule kind when each has its own scene count)."""
    summaries = [load_summary(f, "bench homes") for f in folders]
    rows = [r for f in folders for r in read_output(f)]
    commands = [homes_command(s, f) for f, s in zip(folders, summaries, strict=True)]
    builds = list(dict.fromkeys(c for s in summaries for c in s.get("data_build", ())))
    if len(summaries) == 1:
        return {**summaries[0], "commands": commands, "data_build": builds}, rows
    priors = sorted({str(s.get("prior", DEFAULT_PRIOR)) for s in summaries})
    cameras = {s.get("camera") for s in summaries}
    if len(cameras) > 1:
        raise ObjsearchError(
            f"{', '.join(map(str, folders))} were searched with different cameras "
            f"({', '.join(sorted(str(c) for c in cameras))}): report them apart"
        )
    summary = {
        **homes_summary(rows),
        "commands": commands,
        "data_build": builds,
        "searches": sum(int(s["searches"]) for s in summaries),
        "elapsed_s": round(sum(float(s["elapsed_s"]) for s in summaries), 1),
        "workers": max(int(s["workers"]) for s in summaries),
        "prior": ", ".join(priors),
    }
    if (camera := cameras.pop()) is not None:
        summary["camera"] = camera  # the oracle it measured and the failure causes depend on it
    return summary, rows


def _left_out(title: str, how: str) -> str:
    return f"## {title}\n\nNot in this report: {how}.\n"


def _report_command(inputs: ReportInputs, out: Path, img: Path) -> str:
    words = ["objsearch bench report"]
    words += [f"--paper {inputs.paper}"] if inputs.paper is not None else []
    words += [f"--evaluation {d}" for d in inputs.homes]
    words += [f"--heldout {d}" for d in inputs.heldout or ()]
    words += [f"--table1 {d}" for d in inputs.table1 or ()]
    if inputs.paper_geometric is not None:
        words.append(f"--paper-geometric {inputs.paper_geometric}")
    command = " ".join([*words, f"--out {out}", f"--img {img}"])
    # The report reads the homes (to name each failure's cause) from the data folder it is given.
    data = os.environ.get("OBJSEARCH_DATA")
    return f"OBJSEARCH_DATA={data} {command}" if data else command


def reproduce(
    inputs: ReportInputs,
    paper: dict[str, Any] | None,
    sections: Sequence[dict[str, Any]],
    report_command: str,
) -> list[str]:
    """Every command behind the page, in the order a clean clone runs them: data builds, each
    bench run, then the report itself (each a full command line, never an abbreviation)."""
    data = os.environ.get("OBJSEARCH_DATA")
    builds = [c for s in sections for c in s.get("data_build", ())]
    builds += data_build_commands(Path(data)) if data else []
    runs = (
        []
        if paper is None
        else [paper.get("command", f"objsearch bench paper --out {inputs.paper}")]
    )
    if inputs.paper_geometric is not None:
        other = load_summary(inputs.paper_geometric, "bench paper")
        runs.append(str(other.get("command", "")))
    runs += [str(load_summary(d, "bench table1")["command"]) for d in inputs.table1 or ()]
    runs += [c for s in sections for c in s.get("commands", ())]
    return list(dict.fromkeys([*builds, *(str(r) for r in runs if r), report_command]))


def table1_section(runs: Sequence[dict[str, Any]]) -> str:
    """Table I over FloorPlan sets, one run per reading of Eq. 2 (prior); with several, a
    comparison first: each prior's median per strategy and how often the paper's order holds."""
    parts = ["## Table I over FloorPlan sets\n"]
    if len(runs) > 1:
        parts.append(
            "Each reading of Eq. 2 (`--prior`, docs/paper-readings.md) over its sample "
            "(median of the per-set means, path to discovery m; the paper's WPL ≤ RVP < SDP):\n\n"
            "| prior | sets | SDP | RVP | WPL | paper's order |\n|---|---|---|---|---|---|"
        )
        for run in runs:
            s = run["summary"]
            d, po = s["distribution"], s["paper_order"]
            lo, hi = po["wilson95"]
            parts.append(
                f"| {run['prior']} | {s['sets']} | {d['sdp']['median']:.2f} | "
                f"{d['rvp']['median']:.2f} | {d['wpl']['median']:.2f} | {po['count']} of "
                f"{s['sets']} ({100 * po['share']:.0f} %, CI {100 * lo:.0f}–{100 * hi:.0f} %) |"
            )
        parts.append("")
    for run in runs:
        if len(runs) > 1:
            parts.append(f"### Prior `{run['prior']}`\n")
        parts.append(render_table1(run) + "\n")
    return "\n".join(parts)


#: The page's opening, up to the commands that reproduce it (a ``sh`` block :func:`write_report`
#: fills and closes).
_INTRO = (
    "# Results\n\nGenerated by `objsearch bench report` from the bench outputs named in each "
    "section (with the command that produced it); do not edit by hand. Numbers are "
    "simulation results on this repository's homes (docs/paper-readings.md gives every "
    "reading of the paper they rest on). Path length is the paper's metric — metres to the "
    "discovery of the target — unless a column says 'full path' (which adds the approach to "
    "the target's viewpoint).\n\nThis page, from a clean clone with `../shared` beside "
    "it, in this order (`tests/experiments/test_results_commands.py` checks each parses, "
    "and runs the data builds):\n\n```sh\n"
)
#: The page's last section: the results pages the other benches generate or the docs keep.
_ELSEWHERE = (
    "## Elsewhere\n\nRoutine schedules (where an object is depends on the time of day) and the "
    "belief that knows the hour, with success and SPL beside the oracle ratios: "
    "[results-routine.md](results-routine.md) (`bench belief`). "
    "Schedules taken from real AI2-THOR rearrangement episodes have their own "
    "generated page with its commands, [results-rearrangement.md](results-rearrangement.md) "
    "(`bench report --rearr`); room choice by expected cost and memory of places: "
    "[results-memory.md](results-memory.md); our belief inside a published benchmark's own "
    "task, the Dynamic House Simulator of Kurenkov et al. (ICML 2023), beside its agents: "
    "[results-dhs.md](results-dhs.md) (`bench dhs`); search under a modelled detector and "
    "localiser, by the protocol fixed before its runs (docs/protocol-perception.md): "
    "[results-perception.md](results-perception.md) (`bench belief`).\n"
)

#: What :func:`write_report` does in turn, each named to its ``progress`` as it starts.
REPORT_STAGES = ("runs", "paper", "cameras", "table1", "homes", "held-out")


def write_report(
    inputs: ReportInputs, out: Path, img: Path, progress: Callable[[str], None] | None = None
) -> Path:
    step = progress or (lambda _stage: None)
    step("runs")
    paper = None if inputs.paper is None else load_summary(inputs.paper, "bench paper")
    img.mkdir(parents=True, exist_ok=True)
    # The page links its images relative to itself.
    link = Path(os.path.relpath(img.resolve(), out.resolve().parent)).as_posix()
    homes = load_homes(inputs.homes) if inputs.homes else None
    held = load_homes(inputs.heldout) if inputs.heldout else None
    commands = reproduce(
        inputs,
        paper,
        [run[0] for run in (homes, held) if run is not None],
        _report_command(inputs, out, img),
    )
    sections = [_INTRO + "\n".join(commands) + "\n```\n"]
    step("paper")
    if paper is not None and inputs.paper is not None:
        sections.append(paper_section(paper, inputs.paper, img, link))
    else:
        sections.append(
            _left_out(
                "The paper home: Table I and the long-term experiment (Table II)",
                "run `objsearch bench paper --out out/bench-paper` and pass "
                "`--paper out/bench-paper`",
            )
        )
    step("cameras")
    if inputs.paper_geometric is not None and paper is not None:
        other = load_summary(inputs.paper_geometric, "bench paper")
        sections.append(cameras_section(paper, other, inputs.paper_geometric))
    else:
        sections.append(
            _left_out(
                "The camera",
                "run `objsearch bench paper` with each camera into a folder of its own and "
                "pass them as `--paper DIR --paper-geometric DIR`",
            )
        )
    step("table1")
    if inputs.table1:
        runs = [load_summary(d, "bench table1") for d in inputs.table1]
        sections.append(table1_section(runs))
    else:
        sections.append(
            _left_out(
                "Table I over FloorPlan sets",
                "run `objsearch bench table1 --sets 100 --seed 1 --out out/bench-table1` and pass "
                "`--table1 out/bench-table1`",
            )
        )
    step("homes")
    if homes is not None:
        sections.append(homes_section("Homes (not tuned on)", *homes, img, link, "homes"))
    else:
        sections.append(
            _left_out(
                "Homes (not tuned on)",
                "run `objsearch bench homes --out out/bench-homes` and pass "
                "`--evaluation out/bench-homes`",
            )
        )
    step("held-out")
    if held is not None:
        sections.append(
            homes_section("Held-out homes (looked at only at the end)", *held, img, link, "heldout")
        )
    else:
        sections.append(
            _left_out(
                "Held-out homes (looked at only at the end)",
                "run `objsearch bench homes --homes <held-out homes> --out out/bench-heldout` "
                "and pass `--heldout out/bench-heldout` (never mixed with --evaluation)",
            )
        )
    sections.append(_ELSEWHERE)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(sections), encoding="utf-8")
    return out


__all__ = ["REPORT_STAGES", "ReportInputs", "write_report"]
