"""The paper home's sections of docs/results.md: Table I and the long-term experiment with the
paper's metric and the paper's figures (rendered once, by :func:`experiments.paper.render`), the
difference the camera makes, and the figures drawn from the paper run (route, scene graph)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from objsearch.agent.catalogue import STORE
from objsearch.experiments.paper import render as render_paper
from objsearch.experiments.plots import pyplot, save_figure
from objsearch.experiments.route_map import plot_route_map

#: The data each named prior (docs/paper-readings.md) saw: Visual Genome images (and HOZ's
#: adjacency graph), never AI2-THOR's placements or the homes evaluated.
PRIOR_DATA = {
    "vg-cooccurrence": "Visual Genome image co-occurrence, aliases merged",
    "vg-single-name": "Visual Genome image co-occurrence, one name per class",
    "vg-hoz-masked": "Visual Genome image co-occurrence masked by HOZ's object adjacency",
}
#: A bench summary without a ``camera`` was run before the camera could be chosen: geometric.
UNRECORDED_CAMERA = "geometric"
#: The long-term run whose kept log the scene-graph figure folds (bench paper --keep-logs).
GRAPH_LOG = Path("logs") / "longterm-wpl-all"


def camera(summary: dict[str, Any]) -> str:
    return str(summary.get("camera") or UNRECORDED_CAMERA)


def prior_line(summary: dict[str, Any]) -> str:
    name = str(summary.get("prior", "vg-cooccurrence"))
    return f"prior `{name}` ({PRIOR_DATA.get(name, 'see docs/paper-readings.md')})"


def plot_longterm(summary: dict[str, Any], path: Path) -> list[Path]:
    """Fig. 6-like: mean path length per Table II scene, per strategy and update mode."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 3.6))
    for key, s in summary["longterm"].items():
        scenes = list(s["per_scene"])
        ax.plot(
            [int(x) for x in scenes], [s["per_scene"][x] for x in scenes], marker="o", ms=3,
            label=key,
        )  # fmt: skip
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("scene (Table II)")
    ax.set_ylabel("mean path length (m)")
    ax.set_title("Long-term search on the paper home (8 targets × 8 starts per scene)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False, title="strategy/update")
    return save_figure(fig, path)


def plot_route(
    path: Path, home_name: str = "paper", target: str = "Vase", start: str = "kitchen-1"
) -> str:
    """Fig. 7-like: one WPL search, cut to the rooms it visited, room changes marked."""
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
    found = [p.box.center for p in placements.values() if p.cls == target]
    plot_route_map(
        ctx,
        result.route,
        path,
        title=f"WPL search for the {target} from {start} (paper home, Table I placements), "
        f"{result.path_length:.1f} m",
        start_label=start,
        target=target,
        targets_at=[(c[0], c[1]) for c in found],
    )
    return f"{target} from {start}: {result.path_length:.2f} m, rooms " + " → ".join(
        r for r, _ in result.plans
    )


def plot_graph_before_after(log: Path, path: Path) -> None:
    """Fig. 4-like: Rel before and after the long-term run whose log is ``log`` (the one
    ``bench paper --keep-logs`` kept): Eq. 4, and the same log folded as the Beta posterior."""
    from objsearch.agent.relations import BetaRelations
    from objsearch.agent.scene_graph import SceneGraphProjection
    from objsearch.agent.state import AgentState
    from objsearch.agent.strategies import HALF_LIFE_TASKS, PRIOR_STRENGTH
    from objsearch.events import fold, read_log

    # The run's own fold (Eq. 4, from its spec), the prior alone, and — on purpose, a
    # counterfactual — the same log folded by the Beta model.
    state = fold(read_log(log, store=STORE), AgentState())
    eq4 = state.graph()
    before = SceneGraphProjection()
    beta = BetaRelations(prior_strength=PRIOR_STRENGTH, half_life_tasks=HALF_LIFE_TASKS)
    for e in read_log(log, store=STORE):
        if e.type in ("run_started", "scene_graph_seeded"):
            before.apply(e)
        beta.apply(e)
    tables = [
        ("before (Visual Genome, Eq. 2)", before.as_table()),
        (f"after {state.tasks.ended} searches, Eq. 4", eq4.as_table()),
        ("same log folded as Beta + decay", beta.as_table()),
    ]
    plt = pyplot()
    dyn = sorted(tables[0][1])
    stat = sorted({s for row in tables[0][1].values() for s in row})
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for ax, (title, table) in zip(axes, tables, strict=True):
        grid = [[table[d].get(s, 0.0) for s in stat] for d in dyn]
        im = ax.imshow(grid, vmin=0, vmax=1, cmap="viridis")
        ax.grid(False)
        ax.set_xticks(range(len(stat)))
        ax.set_xticklabels(stat, rotation=70, fontsize=6)
        ax.set_yticks(range(len(dyn)))
        ax.set_yticklabels(dyn, fontsize=7)
        ax.set_title(title, fontsize=8)
    fig.colorbar(im, ax=axes, shrink=0.8, label="Rel (0–1)")
    save_figure(fig, path)


def paper_section(summary: dict[str, Any], folder: Path, img: Path, img_link: str) -> str:
    """Table I and Table II (path to discovery first, the full path beside it, the paper's
    figures in brackets), the long-term plot, and the scene graph before and after."""
    plot_longterm(summary, img / "longterm_per_scene.png")
    lines = [
        "## The paper home: Table I and the long-term experiment (Table II)",
        "",
        f"Command: `{summary.get('command', 'objsearch bench paper')}` — {summary['searches']} "
        f"searches, {summary['elapsed_s']} s with {summary['workers']} process(es). Camera: "
        f"{camera(summary)}; {prior_line(summary)}; SDP seeds "
        f"{summary['table1'].get('sdp', {}).get('seeds', [])}, every other strategy is "
        "deterministic here.",
        "",
        "```",
        render_paper(summary),
        "```",
        f"![path length per scene]({img_link}/longterm_per_scene.png)",
        "",
    ]
    route = plot_route(img / "route_paper_vase.png")
    lines += [f"One WPL search: {route}.", "", f"![route]({img_link}/route_paper_vase.png)", ""]
    log = folder / GRAPH_LOG
    if (log / "meta.json").is_file():
        plot_graph_before_after(log, img / "scene_graph_before_after.png")
        lines += [
            "The scene graph before and after the long-term run (its kept log, folded by Eq. 4 "
            "and by the Beta model with decay: the same events, two projections):",
            "",
            f"![scene graph]({img_link}/scene_graph_before_after.png)",
        ]
    else:
        lines.append(
            f"(No scene-graph figure: {log} is missing; run `objsearch bench paper --keep-logs` "
            "to keep the long-term logs it is drawn from.)"
        )
    return "\n".join(lines) + "\n"


def cameras_section(ours: dict[str, Any], other: dict[str, Any], other_dir: Path) -> str:
    """Both cameras' Table I/II and, per strategy, the difference in path to discovery."""
    a, b = camera(ours), camera(other)
    lines = [
        f"## The camera: {a} against {b}",
        "",
        f"Command ({b}): `{other.get('command', 'objsearch bench paper')}` ({other_dir}); "
        f"{prior_line(other)}. The {a} run is the one above.",
        "",
    ]
    if a == b:
        lines.append(
            f"Both runs used the {a} camera (a summary without `camera` is read as "
            f"{UNRECORDED_CAMERA}): nothing to compare. Pass a run with the other camera."
        )
        return "\n".join(lines) + "\n"
    lines += [
        f"| experiment | strategy | {a} path to discovery m | {b} m | {b} − {a} m "
        f"| {a} success | {b} success |",
        "|---|---|---|---|---|---|---|",
    ]
    for exp in ("table1", "longterm"):
        for name, s in ours[exp].items():
            t = other[exp].get(name)
            if t is None:
                continue
            x, y = s["mean_path_to_discovery"], t["mean_path_to_discovery"]
            lines.append(
                f"| {exp} | {name} | {x:.2f} | {y:.2f} | {y - x:+.2f} "
                f"| {100 * s['success_rate']:.1f} % | {100 * t['success_rate']:.1f} % |"
            )
    lines += ["", f"Table I and II with the {b} camera:", "", "```", render_paper(other), "```"]
    return "\n".join(lines) + "\n"
