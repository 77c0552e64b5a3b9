"""``objsearch bench paper``: the paper's Table I and long-term experiment on the paper home, with
our strategies beside them, metrics, and the paper's own figures for comparison."""

from __future__ import annotations

import json
import math
import statistics
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from objsearch.agent.session import DEFAULT_PRIOR
from objsearch.experiments.metrics import mean_std, summarise
from objsearch.experiments.runner import (
    TARGETS,
    Job,
    Row,
    command_line,
    run_jobs,
    unseeable,
    write_rows,
)
from objsearch.experiments.strategies import PAPER_STRATEGIES, split_strategy, strategy
from objsearch.sim.world import DEFAULT_CAMERA

HOME = "paper"
SDP_SEEDS = 20
#: The paper's Table I (path length in m; SDP's Pillow cell is empty in the paper).
PAPER_TABLE1: dict[str, dict[str, float | None]] = {
    "sdp": dict(
        zip(
            (*TARGETS, "avg"),
            (28.63, 8.88, 20.88, 13.13, 16.25, None, 8.31, 13.88, 14.68),
            strict=True,
        )
    ),
    "rvp": dict(
        zip(
            (*TARGETS, "avg"),
            (15.06, 6.50, 10.63, 8.56, 20.5, 5.75, 8.48, 6.69, 10.27),
            strict=True,
        )
    ),
    "wpl": dict(
        zip(
            (*TARGETS, "avg"),
            (14.25, 6.18, 10.13, 9.00, 19.81, 5.75, 8.48, 6.69, 10.04),
            strict=True,
        )
    ),
}
PAPER_REDUCTION_PCT = -25.27
TABLE1_STRATEGIES = ("sdp", "rvp", "wpl", "epl")  # without updates the relation models coincide
LONGTERM_PAPER_MODES = ("none", "targets", "all")
LONGTERM_OURS = ("wpl-neg", "wpl-neg-decay", "epl", "epl-neg-decay")


def table1_job(
    home: str,
    name: str,
    seed: int,
    targets: Sequence[str],
    prior: str,
    camera: str,
    data: Path | None = None,
) -> Job:
    """One Table I run: strategy ``name`` with ``seed`` on ``home``'s Table I scene (the paper's
    removals), every target from every start, no updates; on the data folder ``data`` (None:
    ``datapaths.data_dir()``)."""
    return Job(
        "table1",
        home,
        "table1",
        name,
        "none",
        seed,
        tuple(targets),
        prior=prior,
        camera=camera,
        data=data,
    )


def paper_jobs(
    strategies: Sequence[str],
    *,
    sdp_seeds: int = SDP_SEEDS,
    targets: Sequence[str] = TARGETS,
    scenes: Sequence[int] | None = None,
    log_root: Path | None = None,
    prior: str = DEFAULT_PRIOR,
    home: str = HOME,
    camera: str = DEFAULT_CAMERA,
) -> list[Job]:
    for name in strategies:
        split_strategy(name)  # unknown names fail here, before any work
    jobs: list[Job] = []
    for name in TABLE1_STRATEGIES:
        if name not in strategies:
            continue
        seeds = range(sdp_seeds) if strategy(name).randomised else range(1)
        jobs += [table1_job(home, name, s, targets, prior, camera) for s in seeds]
    for name in strategies:
        if split_strategy(name)[0].name in ("sdp", "rvp"):
            continue  # the paper runs its long-term experiment with its own method
        modes = LONGTERM_PAPER_MODES if name == "wpl" else ("all",)
        for mode in modes:
            log = str(log_root / f"longterm-{name}-{mode}") if log_root else None
            jobs.append(
                Job(
                    "longterm",
                    home,
                    "table2",
                    name,
                    mode,
                    0,
                    tuple(targets),
                    tuple(scenes) if scenes else None,
                    log_dir=log,
                    prior=prior,
                    camera=camera,
                )
            )
    return jobs


def discovery(row: Row) -> float:
    """The paper's path length: metres to the detection (the whole path if never found)."""
    return row.path_length if row.path_to_discovery is None else row.path_to_discovery


def _cell(v: float | None) -> str:
    return "–" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.2f}"


def table1_summary(rows: Sequence[Row]) -> dict[str, Any]:
    t1 = [r for r in rows if r.experiment == "table1"]
    out: dict[str, Any] = {}
    targets = [t for t in TARGETS if any(r.target == t for r in t1)]
    for name in dict.fromkeys(r.strategy for r in t1):
        mine = [r for r in t1 if r.strategy == name]
        seeds = sorted({r.seed for r in mine})
        per_seed = [statistics.fmean(discovery(r) for r in mine if r.seed == s) for s in seeds]
        per_target = {}
        for t in targets:
            vals = [
                statistics.fmean(discovery(r) for r in mine if r.seed == s and r.target == t)
                for s in seeds
            ]
            m, sd = mean_std(vals)
            per_target[t] = {"mean": m, "std_over_seeds": sd}
        m, sd = mean_std(per_seed)
        out[name] = {
            **summarise(mine),
            "mean_path_to_discovery": m,
            "mean_approach": statistics.fmean(r.path_length - discovery(r) for r in mine),
            "seeds": seeds,
            "avg_std_over_seeds": sd,
            "avg_min_max_over_seeds": [min(per_seed), max(per_seed)],
            "per_target": per_target,
            "paper": PAPER_TABLE1.get(name),
        }
    return out


def longterm_summary(rows: Sequence[Row]) -> dict[str, Any]:
    lt = [r for r in rows if r.experiment == "longterm"]
    out: dict[str, Any] = {}
    base_rows = [r for r in lt if r.strategy == "wpl" and r.update_mode == "none"]
    base = statistics.fmean(discovery(r) for r in base_rows) if base_rows else math.nan
    for key in dict.fromkeys((r.strategy, r.update_mode) for r in lt):
        mine = [r for r in lt if (r.strategy, r.update_mode) == key]
        scenes = sorted({r.scene for r in mine})
        s = summarise(mine)
        to_discovery = statistics.fmean(discovery(r) for r in mine)
        out[f"{key[0]}/{key[1]}"] = {
            **s,
            "mean_path_to_discovery": to_discovery,
            "strategy": key[0],
            "update_mode": key[1],
            "per_scene": {
                str(sc): statistics.fmean(discovery(r) for r in mine if r.scene == sc)
                for sc in scenes
            },
            "change_vs_wpl_none_pct": 100 * (to_discovery - base) / base if base == base else None,
        }
    return out


def render(summary: dict[str, Any]) -> str:
    lines: list[str] = []
    t1 = summary["table1"]
    if t1:
        targets = [t for t in TARGETS if t in next(iter(t1.values()))["per_target"]]
        lines.append(
            "Table I — path length to discovery (m; the paper's metric) per target, mean over 8 "
            "starts (paper's figures in brackets); 'path+appr' adds the approach to the target"
        )
        lines.append(
            f"{'strategy':10}"
            + "".join(f"{t[:11]:>19}" for t in targets)
            + f"{'avg':>19}{'path+appr':>11}"
        )
        for name, s in t1.items():
            paper = s["paper"] or {}
            cells = []
            for t in targets:
                pt = s["per_target"][t]
                v = f"{pt['mean']:.2f}" + (
                    f"±{pt['std_over_seeds']:.2f}" if len(s["seeds"]) > 1 else ""
                )
                cells.append(f"{v} [{_cell(paper.get(t))}]" if paper else v)
            avg = f"{s['mean_path_to_discovery']:.2f}" + (
                f"±{s['avg_std_over_seeds']:.2f}" if len(s["seeds"]) > 1 else ""
            )
            cells.append(f"{avg} [{_cell(paper.get('avg'))}]" if paper else avg)
            lines.append(
                f"{name:10}"
                + "".join(f"{c:>19}" for c in cells)
                + f"{s['mean_path_length']:>11.2f}"
            )
        lines.append("")
    lt = summary["longterm"]
    if lt:
        scenes = list(next(iter(lt.values()))["per_scene"])
        lines.append(
            "Long-term (Table II schedule) — mean path length to discovery (m) per scene over "
            "8 targets × 8 starts; 'path+appr' adds the approach to the target"
        )
        lines.append(
            f"{'strategy/updates':22}"
            + "".join(f"{s:>7}" for s in scenes)
            + f"{'avg':>8}{'vs none':>10}{'path+appr':>11}"
        )
        for key, s in lt.items():
            ch = s["change_vs_wpl_none_pct"]
            lines.append(
                f"{key:22}"
                + "".join(f"{s['per_scene'][sc]:7.2f}" for sc in scenes)
                + f"{s['mean_path_to_discovery']:8.2f}"
                + (f"{ch:+9.2f}%" if ch is not None else f"{'–':>10}")
                + f"{s['mean_path_length']:11.2f}"
            )
        lines.append(f"(the paper reports {PAPER_REDUCTION_PCT:+.2f} % with updates)")
        lines.append("")
    lines.append("Metrics (all searches of each run; full path, with the approach to the target)")
    lines.append(
        f"{'experiment':10} {'strategy/updates':22}{'n':>6}{'full m':>9}{'success':>9}{'SPL':>7}{'oracle×':>9}"
    )
    for exp in ("table1", "longterm"):
        for key, s in summary[exp].items():
            lines.append(
                f"{exp:10} {key:22}{s['n']:6d}{s['mean_path_length']:9.2f}{s['success_rate']:9.1%}"
                f"{s['spl']:7.3f}{s['oracle_ratio']:9.2f}"
            )
    return "\n".join(lines)


def run_paper(
    out: Path,
    *,
    strategies: Sequence[str],
    sdp_seeds: int = SDP_SEEDS,
    workers: int = 2,
    progress: bool = True,
    as_json: bool = False,
    targets: Sequence[str] = TARGETS,
    scenes: Sequence[int] | None = None,
    keep_logs: bool = False,
    prior: str = DEFAULT_PRIOR,
    camera: str = DEFAULT_CAMERA,
) -> dict[str, Any]:
    out.mkdir(parents=True, exist_ok=True)
    jobs = paper_jobs(
        strategies,
        sdp_seeds=sdp_seeds,
        targets=targets,
        scenes=scenes,
        log_root=out / "logs" if keep_logs else None,
        prior=prior,
        camera=camera,
    )
    started = time.perf_counter()
    rows = run_jobs(jobs, workers=workers, progress=progress, label="bench paper")
    elapsed = time.perf_counter() - started
    parquet, csv = write_rows(rows, out, "paper_trials")
    summary = {
        "home": HOME,
        "command": command_line(
            "objsearch bench paper",
            {
                "out": out,
                "strategies": list(strategies),
                "sdp_seeds": sdp_seeds,
                "targets": None if tuple(targets) == TARGETS else list(targets),
                "scenes": list(scenes) if scenes else None,
                "prior": None if prior == DEFAULT_PRIOR else prior,
                "camera": None if camera == DEFAULT_CAMERA else camera,
                "keep_logs": keep_logs,
                "workers": workers,
            },
        ),
        "prior": prior,
        "camera": camera,
        "sdp_seeds": sdp_seeds,
        "workers": workers,
        "elapsed_s": round(elapsed, 1),
        "searches": len(rows),
        "unseeable": unseeable(jobs),
        "table1": table1_summary(rows),
        "longterm": longterm_summary(rows),
        "paper": {"table1": PAPER_TABLE1, "longterm_reduction_pct": PAPER_REDUCTION_PCT},
        "files": {"parquet": parquet.name, "csv": csv.name},
    }
    summary["strategies"] = per_strategy(summary)
    (out / "summary.json").write_text(
        json.dumps(summary, indent=2, default=_json_default) + "\n", encoding="utf-8"
    )
    (out / "tables.txt").write_text(render(summary) + "\n", encoding="utf-8")
    return summary


def per_strategy(summary: dict[str, Any]) -> dict[str, Any]:
    """The machine-readable core: per experiment and strategy, the four headline metrics."""
    keys = ("mean_path_length", "success_rate", "spl", "oracle_ratio")
    return {
        exp: {name: {k: s[k] for k in keys} for name, s in summary[exp].items()}
        for exp in ("table1", "longterm")
    }


def figures(summary: dict[str, Any]) -> dict[str, Any]:
    """``bench paper --format json``: the figures :func:`render` prints, rounded as it rounds
    them (metres to 2 decimals, changes to 2), beside the paper's: Table I's path to discovery
    per strategy and target, and the long-term experiment's per scene."""

    def m(v: float | None) -> float | None:
        return None if v is None or math.isnan(v) else round(v, 2)

    table1 = {
        name: {
            "path_to_discovery_m": m(s["mean_path_to_discovery"]),
            "std_over_seeds_m": m(s["avg_std_over_seeds"]) if len(s["seeds"]) > 1 else None,
            "full_path_m": m(s["mean_path_length"]),
            "per_target_m": {t: m(v["mean"]) for t, v in s["per_target"].items()},
            "paper_m": s["paper"],
        }
        for name, s in summary["table1"].items()
    }
    longterm = {
        key: {
            "path_to_discovery_m": m(s["mean_path_to_discovery"]),
            "full_path_m": m(s["mean_path_length"]),
            "per_scene_m": {sc: m(v) for sc, v in s["per_scene"].items()},
            "change_vs_wpl_none_pct": m(s["change_vs_wpl_none_pct"]),
        }
        for key, s in summary["longterm"].items()
    }
    return {
        "table1": table1,
        "longterm": longterm,
        "paper_longterm_reduction_pct": PAPER_REDUCTION_PCT,
    }


def _json_default(o: object) -> object:
    if isinstance(o, float) and math.isnan(o):
        return None
    raise TypeError(type(o))


__all__ = ["PAPER_STRATEGIES", "figures", "run_paper"]
