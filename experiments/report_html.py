"""The reports as web pages: ``bench report --html`` (the results page as ``index.html``) and
``audit --html`` (an index of tasks and a page per task: its anomalies, route, the relation
values behind each plan, the update and the timeline). Every page is self-contained
(experiments/html.py): open ``index.html`` from disk."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

from objsearch.agent.session import load_context
from objsearch.experiments.html import bar, document, esc, figure, markdown, table
from objsearch.experiments.route_map import plot_route_map, walked

INDEX = "index.html"


def write_results_html(page: Path, out: Path | None = None) -> Path:
    """``page`` (a results Markdown page whose images have SVG twins) as one HTML file,
    ``index.html`` beside it unless ``out`` says otherwise."""
    target = out or page.parent / INDEX
    body = markdown(page.read_text(encoding="utf-8"), page.parent)
    title = "objsearch results"
    target.write_text(document(title, body, nav=[(title, target.name)]), encoding="utf-8")
    return target


def page_name(task_id: str) -> str:
    """The file a task's page is written to (as the Markdown audit names its pages)."""
    return task_id.replace("(", "").replace(")", "").replace(" ", "-") + ".html"


def _route(task: Any, folder: Path) -> str:
    """The task's route figure, inline; empty when it has no route or no home."""
    if not task.home or len(task.route) < 2:
        return ""
    ctx = load_context(task.home)
    png = folder / f"{page_name(task.task_id)}.png"
    length = f", {task.path_length:.1f} m" if task.path_length is not None else ""
    plot_route_map(
        ctx,
        walked(ctx.navmap, task.route),
        png,
        title=f"{task.task_id}: find {task.target} from {task.start}{length}",
        start_label=task.start,
        target=f"{task.target} (found)" if task.found_at else f"{task.target} (not found)",
        targets_at=[(task.found_at.x, task.found_at.y)] if task.found_at else [],
    )
    return figure(png, "route, cut to the rooms visited; diamonds: room changes in travel order")


def _result(task: Any) -> str:
    return "found" if task.success else ("not found" if task.success is False else "?")


def _task_page(task: Any, route: str, title: str) -> str:
    parts = [f"<h1>{esc(task.task_id)}: find {esc(task.target)} from {esc(task.start)}</h1>"]
    oracle = f"{task.oracle_length:.2f} m" if task.oracle_length is not None else "–"
    length = f"{task.path_length:.2f} m" if task.path_length is not None else "–"
    parts.append(
        f"<p>{esc(_result(task))}; path {esc(length)}; straight to the object (oracle) "
        f"{esc(oracle)}; home {esc(task.home or '?')}; events {task.first_seq}–{task.last_seq}.</p>"
    )
    if task.anomalies:
        parts.append("<h2>Anomalies</h2>")
        parts.append(
            table(["seq", "kind", "what"], [[a.seq, a.kind, a.message] for a in task.anomalies])
        )
    if route:
        parts += ["<h2>Route</h2>", route]
    parts.append("<h2>Relation values behind each plan</h2>")
    if not task.plans:
        parts.append("<p>No plan in this task.</p>")
    for plan in task.plans:
        parts.append(
            f"<h3>seq {plan['seq']}: {esc(plan['room'])} ({esc(plan.get('objective', ''))}, "
            f"objective {float(plan['value']):.4f})</h3><p>rooms left: "
            f"{esc(', '.join(plan['room_order']) or 'none')}</p>"
        )
        rows: list[list[str | int | float | None]] = []
        for c in plan["candidates"]:
            rel = float(c["rel"])
            rank = (
                plan["order"].index(c["static_id"]) + 1 if c["static_id"] in plan["order"] else None
            )
            rows.append([rank, c["static_id"].split("/", 1)[-1], rel, bar(rel)])
        rows.sort(key=lambda r: r[0] if isinstance(r[0], int) else 10**9)
        parts.append(table(["visit #", "static object", "Rel", ""], rows, raw=(3,), digits=4))
    parts.append("<h2>Experience and the update</h2>")
    parts.append(
        "<ul>" + "".join(f"<li>{esc(u)}</li>" for u in task.updates) + "</ul>"
        if task.updates
        else "<p>The task did not end.</p>"
    )
    parts.append("<h2>Timeline</h2>")
    events = []
    for line in task.timeline:
        seq, _, what = line.partition(": ")
        events.append([int(seq) if seq.isdigit() else seq, what])
    parts.append(table(["seq", "event"], events))
    return document(f"{task.task_id} — {title}", "".join(parts), nav=[(f"← {title}", INDEX)])


def write_audit_html(
    auditor: Any, out: Path, *, plots: str = "flagged", max_plots: int | None = 25, title: str
) -> list[Path]:
    """``index.html`` (every task, sortable, anomalies counted) and a page per task; routes are
    drawn for the tasks ``plots`` names (all, flagged, none), at most ``max_plots``."""
    written: list[Path] = []
    rows: list[list[str | int | float | None]] = []
    flagged: list[str] = []
    counts: dict[str, int] = {}
    drawn = 0
    with tempfile.TemporaryDirectory() as tmp:
        for task in auditor.tasks:
            for a in task.anomalies:
                counts[a.kind] = counts.get(a.kind, 0) + 1
            wanted = plots == "all" or (plots == "flagged" and bool(task.anomalies))
            route = ""
            if wanted and (max_plots is None or drawn < max_plots):
                route = _route(task, Path(tmp))
                drawn += bool(route)
            name = page_name(task.task_id)
            (out / name).write_text(_task_page(task, route, title), encoding="utf-8")
            written.append(out / name)
            ratio = (
                task.path_length / task.oracle_length
                if task.path_length is not None and task.oracle_length
                else None
            )
            kinds = ", ".join(sorted({a.kind for a in task.anomalies}))
            rows.append(
                [
                    f'<a href="{esc(name)}">{esc(task.task_id)}</a>',
                    task.target,
                    task.start,
                    _result(task),
                    task.path_length,
                    task.oracle_length,
                    ratio,
                    len(task.plans),
                    kinds or "–",
                ]
            )
            flagged.append("flagged" if task.anomalies else "")
    summary = ", ".join(f"{k} {v}" for k, v in sorted(counts.items())) or "none"
    body = (
        f"<h1>{esc(title)}</h1><p>{len(auditor.tasks)} tasks; anomalies: {esc(summary)}. "
        "Click a column to sort; flagged tasks are shaded; each task's page has its route, "
        "the relation values behind each plan and its timeline.</p>"
        + table(
            [
                "task",
                "target",
                "start",
                "result",
                "path m",
                "oracle m",
                "÷ oracle",
                "plans",
                "anomalies",
            ],
            rows,
            raw=(0,),
            row_class=flagged,
        )
    )
    (out / INDEX).write_text(document(title, body, nav=[(title, INDEX)]), encoding="utf-8")
    return [out / INDEX, *written]


__all__ = ["INDEX", "page_name", "write_audit_html", "write_results_html"]
