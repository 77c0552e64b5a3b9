"""``objsearch bench report``: docs/results.md and its plots, generated from bench outputs."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from objsearch.agent.errors import ObjsearchError
from objsearch.experiments.homes import render as render_homes
from objsearch.experiments.paper import PAPER_REDUCTION_PCT
from objsearch.experiments.paper import render as render_paper


def _load(folder: Path) -> dict[str, Any]:
    path = folder / "summary.json"
    if not path.is_file():
        raise ObjsearchError(f"no bench summary at {path}; run `objsearch bench` first")
    doc: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return doc


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_longterm(summary: dict[str, Any], path: Path) -> None:
    """Fig. 6-like: mean path length per Table II scene, per strategy and update mode."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 4), dpi=100)
    for key, s in summary["longterm"].items():
        scenes = list(s["per_scene"])
        ax.plot(
            [int(x) for x in scenes], [s["per_scene"][x] for x in scenes], marker="o", label=key
        )
    ax.set_xlabel("scene (Table II)")
    ax.set_ylabel("mean path length (m)")
    ax.set_title("Long-term search on the paper home (8 targets × 8 starts per scene)")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_homes(summary: dict[str, Any], path: Path) -> None:
    """Mean path length per held-out home and strategy."""
    plt = _plt()
    homes = list(summary["by_home"])
    keys = list(summary["overall"])
    fig, ax = plt.subplots(figsize=(max(8, len(homes) * 0.45), 4), dpi=100)
    width = 0.8 / len(keys)
    for i, k in enumerate(keys):
        vals = [summary["by_home"][h].get(k, {}).get("mean_path_length", math.nan) for h in homes]
        ax.bar([x + i * width for x in range(len(homes))], vals, width, label=k)
    ax.set_xticks([x + 0.4 - width / 2 for x in range(len(homes))])
    ax.set_xticklabels(homes, rotation=60, ha="right", fontsize=7)
    ax.set_ylabel("mean path length (m)")
    ax.set_title("Held-out homes: mean path length per strategy (updates of all pairs)")
    ax.legend(fontsize=7, ncol=4)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_route(
    path: Path, home_name: str = "paper", target: str = "Vase", start: str = "kitchen-1"
) -> str:
    """Fig. 7-like: one WPL search drawn over the home's viewpoints and static objects."""
    import tempfile

    from objsearch.agent.scene_graph import UpdateMode
    from objsearch.agent.session import Session, load_context
    from objsearch.agent.strategies import RunSpec
    from objsearch.sim.placements import base_placements, table1_removals
    from objsearch.sim.world import SimWorld

    ctx = load_context(home_name)
    placements = base_placements(ctx.home, table1_removals(ctx.home))
    with tempfile.TemporaryDirectory() as tmp:
        spec = RunSpec.of(ctx.home.name, ctx.home.digest, "wpl", update_mode=UpdateMode.NONE)
        session = Session.start(ctx, Path(tmp), spec)
        try:
            world = SimWorld(ctx.home, ctx.navmap, placements, ctx.home.start(start))
            result = session.search(world, target, start)
        finally:
            session.close()
    plt = _plt()
    fig, ax = plt.subplots(figsize=(10, 3.6), dpi=100)
    pts = list(ctx.navmap.room_of)
    ax.scatter([p.x for p in pts], [p.y for p in pts], s=2, c="#cccccc", label="viewpoints")
    for s in ctx.semmap.statics:
        ax.add_patch(
            plt.Rectangle(
                (s.box.center[0] - s.box.size[0] / 2, s.box.center[1] - s.box.size[1] / 2),
                s.box.size[0],
                s.box.size[1],
                fill=False,
                ec="#4477aa",
                lw=0.8,
            )
        )
        ax.annotate(s.cls, (s.loc.x, s.loc.y), fontsize=5, color="#4477aa")
    xs, ys = [p.x for p in result.route], [p.y for p in result.route]
    # Teleports between doors are drawn as separate segments (no walking between them).
    seg_x, seg_y = [xs[0]], [ys[0]]
    for x, y in zip(xs[1:], ys[1:], strict=True):
        if math.hypot(x - seg_x[-1], y - seg_y[-1]) > 0.5:
            ax.plot(seg_x, seg_y, c="#cc3311", lw=1.5)
            seg_x, seg_y = [], []
        seg_x.append(x)
        seg_y.append(y)
    ax.plot(seg_x, seg_y, c="#cc3311", lw=1.5, label=f"route ({result.path_length:.1f} m)")
    ax.scatter([xs[0]], [ys[0]], c="green", s=30, zorder=3, label=f"start {start}")
    found = [p for p in placements.values() if p.cls == target]
    ax.scatter(
        [p.box.center[0] for p in found],
        [p.box.center[1] for p in found],
        marker="*",
        s=90,
        c="gold",
        ec="k",
        zorder=3,
        label=target,
    )
    ax.set_aspect("equal")
    ax.set_title(f"WPL search for the {target} from {start} (paper home, Table I placements)")
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return f"{target} from {start}: {result.path_length:.2f} m, rooms " + " → ".join(
        r for r, _ in result.plans
    )


def plot_graph_before_after(path: Path) -> None:
    """Fig. 4-like: Rel before and after the long-term run (Eq. 4, and the Beta posterior)."""
    import tempfile

    from objsearch.agent.relations import BetaRelations
    from objsearch.agent.scene_graph import SceneGraphProjection
    from objsearch.agent.state import AgentState
    from objsearch.agent.strategies import HALF_LIFE_TASKS, PRIOR_STRENGTH
    from objsearch.events import fold, read_log
    from objsearch.experiments.runner import Job, run_job

    tables = []
    with tempfile.TemporaryDirectory() as tmp:
        run_job(Job("longterm", "paper", "table2", "wpl", "all", log_dir=tmp))
        # The run's own fold (Eq. 4, from its spec), the prior alone, and — on purpose, a
        # counterfactual — the same log folded by the Beta model.
        eq4 = fold(read_log(Path(tmp)), AgentState()).graph()
        before = SceneGraphProjection()
        beta = BetaRelations(prior_strength=PRIOR_STRENGTH, half_life_tasks=HALF_LIFE_TASKS)
        for e in read_log(Path(tmp)):
            if e.type in ("run_started", "scene_graph_seeded"):
                before.apply(e)
            beta.apply(e)
        tables = [
            ("before (Visual Genome, Eq. 2)", before.as_table()),
            ("after 640 searches, Eq. 4", eq4.as_table()),
            ("same log folded as Beta + decay", beta.as_table()),
        ]
    plt = _plt()
    dyn = sorted(tables[0][1])
    stat = sorted({s for row in tables[0][1].values() for s in row})
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), dpi=100)
    for ax, (title, table) in zip(axes, tables, strict=True):
        grid = [[table[d].get(s, 0.0) for s in stat] for d in dyn]
        im = ax.imshow(grid, vmin=0, vmax=1, cmap="viridis")
        ax.set_xticks(range(len(stat)))
        ax.set_xticklabels(stat, rotation=70, fontsize=6)
        ax.set_yticks(range(len(dyn)))
        ax.set_yticklabels(dyn, fontsize=7)
        ax.set_title(title, fontsize=8)
    fig.colorbar(im, ax=axes, shrink=0.8, label="Rel")
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)


def write_report(paper_dir: Path, homes_dir: Path, out: Path, img: Path) -> Path:
    paper = _load(paper_dir)
    homes = _load(homes_dir)
    img.mkdir(parents=True, exist_ok=True)
    Path("img") if img.resolve().parent == out.resolve().parent else img
    plot_longterm(paper, img / "longterm_per_scene.png")
    plot_homes(homes, img / "heldout_homes.png")
    route = plot_route(img / "route_paper_vase.png")
    plot_graph_before_after(img / "scene_graph_before_after.png")
    t1 = paper["table1"]
    lt = paper["longterm"]
    red = {k: v["change_vs_wpl_none_pct"] for k, v in lt.items()}
    sdp = t1.get("sdp", {})
    strategies = [k for k in homes["overall"] if "/" not in k]
    rvp_pt = t1.get("rvp", {}).get("per_target", {})
    wpl_pt = t1.get("wpl", {}).get("per_target", {})
    rvp_worst = (
        ", ".join(
            f"{t} ({rvp_pt[t]['mean']:.2f} m vs WPL {wpl_pt[t]['mean']:.2f} m)"
            for t in sorted(
                rvp_pt, key=lambda t: -(rvp_pt[t]["mean"] - wpl_pt.get(t, {}).get("mean", 0))
            )[:2]
        )
        if rvp_pt and wpl_pt
        else "n/a"
    )
    homes_cmd = (
        f"objsearch bench homes --out {homes_dir} --homes {','.join(homes['homes'])} "
        f"--seeds {len(homes['seeds'])} --scenes {homes['scenes']} --strategies {','.join(strategies)}"
    )
    best = min(strategies, key=lambda k: homes["overall"][k]["mean_path_length"])
    b, w = homes["overall"][best], homes["overall"].get("wpl", {})
    verdict = (
        f"On the held-out homes the lowest mean path length is **{best}** "
        f"({b['mean_path_length']:.2f} m vs WPL {w.get('mean_path_length', math.nan):.2f} m, "
        f"below WPL in {b['runs_better_than_wpl']} home/schedule runs). The paper's WPL stays the "
        "default (`SearchConfig`, `objsearch search/demo`) until a larger held-out run (more "
        "schedule seeds, all ten scenes) confirms it; this run is one schedule per home."
    )
    text = (
        f"""# Results

Generated by `objsearch bench report` from the outputs of the commands below; do not edit by hand.
Numbers are simulation results on this repository's homes (see docs/paper-readings.md for every
reading of the paper that they rest on).

## Commands and seeds
```
objsearch bench paper --out {paper_dir}
#   {paper["searches"]} searches, {paper["elapsed_s"]} s with {paper["workers"]} processes (shared, loaded machine)
{homes_cmd}
#   {homes["searches"]} searches, {homes["elapsed_s"]} s with {homes["workers"]} processes
objsearch bench report --paper {paper_dir} --homes {homes_dir}
```
Seeds: SDP's random room order uses seeds {sdp.get("seeds", [])} (Table I); every other strategy is
deterministic on the paper home. Held-out schedules are `stats-<seed>` for seeds {homes["seeds"]}
(drawn from AI2-THOR placement statistics, `sim/stats_schedule.py`); SDP there uses the same seed.
Held-out iTHOR homes were chosen by the seeded rule in `pipeline/more_homes.py` (seed 3) before any
result was seen; the Beta prior strength (2) and decay half-life (64 tasks) were fixed a priori.

## The paper home
```
{render_paper(paper)}
```
![path length per scene](img/longterm_per_scene.png)

### Where and why we differ from the paper
- **Table I lengths are about twice the paper's** (WPL {t1.get("wpl", {}).get("mean_path_length", math.nan):.2f} m
  vs 10.04 m; SDP {sdp.get("mean_path_length", math.nan):.2f} ± {sdp.get("avg_std_over_seeds", math.nan):.2f} m over
  {len(sdp.get("seeds", []))} seeds vs 14.68 m). The paper's start points, camera model and stopping
  rule are unpublished; ours are in docs/paper-readings.md (starts: the two viewpoints of a room
  farthest apart; detection needs a 100 px mask from a 640×480, 90° camera; the walk ends at the
  target's nearest viewpoint). Far-apart starts make every walk longer, including the oracle's
  ({t1.get("wpl", {}).get("mean_oracle_length", math.nan):.2f} m on average), so the oracle ratio is the fairer comparison.
- **The ranking differs**: in our home RVP ({t1.get("rvp", {}).get("mean_path_length", math.nan):.2f} m) is worse than
  SDP, whereas the paper has RVP ≈ WPL < SDP. RVP ignores distance, so wherever the Visual Genome
  prior ranks a far static class first it walks there first; its worst targets here are
  {rvp_worst}. Which targets suffer depends on where this home keeps them (the paper saw the
  same effect for Laptop and Vase in its home).
- **Long-term**: the paper reports {PAPER_REDUCTION_PCT:+.2f} % with updates; we measure
  {red.get("wpl/all", math.nan):+.2f} % (all pairs) and {red.get("wpl/targets", math.nan):+.2f} % (target pairs only)
  for the paper's method. Our strategies: """
        + ", ".join(
            f"{k} {v:+.2f} %" for k, v in red.items() if v is not None and not k.startswith("wpl/")
        )
        + f""".

## Held-out homes (not tuned on)
{len(homes["homes"])} homes: {", ".join(homes["homes"])}. Every strategy, updates of all pairs,
{homes["scenes"]} scenes per schedule, 8 targets (a target with no possible receptacle in a home
is left out), every start of every room. `< wpl` counts the (home, schedule) runs where a
strategy's mean path length is below the paper's WPL.
```
{render_homes(homes)}
```
![held-out homes](img/heldout_homes.png)

{verdict}

Schedules taken from real AI2-THOR rearrangement episodes (`rearr-<seed>`, iTHOR homes) have
their own generated page: [results-rearrangement.md](results-rearrangement.md)
(`objsearch bench report --rearr <bench homes output>`).

Table I over a seeded sample of the FloorPlan sets that satisfy the paper's removal rule, with
the paper's figures and our paper home placed in the distribution, has its own page:
[results-table1.md](results-table1.md) (`objsearch bench table1 --sets 100 --seed 1`).

## Route and scene graph
{route}.

![route](img/route_paper_vase.png)

The scene graph before and after the long-term run (one log, folded by Eq. 4 and by the Beta model
with decay: the same events, two projections):

![scene graph](img/scene_graph_before_after.png)
"""
    )
    out.write_text(text, encoding="utf-8")
    return out


__all__ = ["write_report"]
