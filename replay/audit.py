"""Audit a log task by task: what the robot saw, learned and decided, and what looks wrong.

Anomalies flagged (each with the event sequence numbers that show it):

- ``target-not-acted-on``: an accepted detection of the target, after which the robot went on
  planning, looking or failed instead of approaching it;
- ``stale-plan``: a plan whose relation values are not the scene graph's at that point of the log;
- ``far-above-oracle``: path length above ``ORACLE_RATIO`` × and ``ORACLE_EXCESS_M`` more than the
  walk straight from the start to the found object's nearest viewpoint;
- ``out-of-order``: time running backwards, a task event outside a task, a task that never ended,
  a ``task_ended`` path length that is not the sum of the task's ``moved`` metres.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from objsearch.agent.catalogue import (
    Candidate,
    ContainerOpened,
    Detected,
    Moved,
    PlanComputed,
    SearchFailed,
    TargetFound,
    TaskAborted,
    TaskEnded,
    TaskStarted,
    ViewTaken,
    decode,
)
from objsearch.agent.geometry import Point
from objsearch.agent.outdir import claim
from objsearch.agent.relations import instance_value, per_instance
from objsearch.agent.session import load_context
from objsearch.agent.state import AgentState
from objsearch.agent.stops import stop_statics, stop_value
from objsearch.agent.strategies import AGENT_MODELS, RelationModels
from objsearch.replay.state import ReplayState

ORACLE_RATIO = 5.0
ORACLE_EXCESS_M = 10.0
REL_TOLERANCE = 1e-9


@dataclass(frozen=True, slots=True)
class Anomaly:
    kind: str
    seq: int
    message: str


@dataclass
class TaskAudit:
    """One task as the log tells it."""

    task_id: str
    target: str = ""
    start: str = ""
    home: str = ""
    first_seq: int = 0
    last_seq: int = 0
    success: bool | None = None
    path_length: float | None = None
    oracle_length: float | None = None
    route: list[Point] = field(default_factory=list)  # start, then where each move ended
    found_at: Point | None = None
    timeline: list[str] = field(default_factory=list)
    plans: list[dict[str, Any]] = field(default_factory=list)
    learned: dict[str, list[str]] = field(default_factory=dict)
    updates: list[str] = field(default_factory=list)
    anomalies: list[Anomaly] = field(default_factory=list)
    _moved_metres: float = 0.0
    _target_seen_at: int | None = None

    def flag(self, kind: str, seq: int, message: str) -> None:
        self.anomalies.append(Anomaly(kind, seq, message))


class Auditor:
    """Folds a log and builds a :class:`TaskAudit` per task."""

    def __init__(
        self,
        *,
        oracle_ratio: float = ORACLE_RATIO,
        oracle_excess_m: float = ORACLE_EXCESS_M,
        models: RelationModels = AGENT_MODELS,
    ) -> None:
        self.oracle_ratio = oracle_ratio
        self.oracle_excess_m = oracle_excess_m
        self.state = ReplayState(AgentState(models=models))
        self.tasks: list[TaskAudit] = []
        self.log_anomalies: list[Anomaly] = []
        self._current: TaskAudit | None = None
        self._last_time = -1

    def feed(self, events: Iterable[Any]) -> None:
        for event in events:
            self._before(event)
            self.state.apply(event)
            self._after(event)
        if self._current is not None:
            self._current.flag(
                "out-of-order", self._current.last_seq, "the task never ended (log stops here)"
            )
            self._finish(self._current)

    def _before(self, event: Any) -> None:
        if event.time_ns < self._last_time:
            self._where(event).flag(
                "out-of-order", event.seq, f"time runs backwards ({event.time_ns} ns)"
            )
        self._last_time = event.time_ns
        task = self._current
        if event.type == "plan_computed" and task is not None:
            self._check_plan(task, event)

    def _where(self, event: Any) -> TaskAudit:
        if self._current is not None:
            return self._current
        holder = TaskAudit(task_id="(outside any task)")
        self.tasks.append(holder)
        return holder

    def _value(self, task: TaskAudit, room: str, candidate: Candidate) -> float:
        """What the graph says the candidate stop is worth now (per instance where it can)."""
        graph = self.state.graph
        if not per_instance(graph):
            return graph.rel(task.target, candidate.static_class)
        semmap = load_context(task.home).semmap
        key = next((s for s in semmap.in_room(room) if s.id == candidate.static_id), None)
        if key is None:
            return graph.rel(task.target, candidate.static_class)
        group = [
            s
            for s in stop_statics(semmap, room, key)
            if instance_value(graph, task.target, s.id, s.cls) > 0
        ]
        return stop_value(graph, task.target, group or [key])

    def _check_plan(self, task: TaskAudit, event: Any) -> None:
        plan = decode(event, PlanComputed)
        now = [(c, self._value(task, plan.room, c)) for c in plan.candidates]
        stale = [
            f"{c.static_class}: logged {c.rel:.4f}, graph {value:.4f}"
            for c, value in now
            if abs(c.rel - value) > REL_TOLERANCE
        ]
        if stale:
            task.flag(
                "stale-plan",
                event.seq,
                f"plan for {plan.room} used relation values the scene graph no longer had: "
                + "; ".join(stale),
            )
        if task._target_seen_at is not None:
            self._not_acted_on(task, event.seq, "planned another room")

    def _not_acted_on(self, task: TaskAudit, seq: int, what: str) -> None:
        seen = task._target_seen_at
        task.flag(
            "target-not-acted-on",
            seq,
            f"the target {task.target} was detected at seq {seen} but the robot {what}",
        )
        task._target_seen_at = None

    def _after(self, event: Any) -> None:
        kind = event.type
        if kind == "task_started":
            self._task_started(event)
            return
        task = self._current
        if task is None:
            if event.task_id is not None:
                self._where(event).flag(
                    "out-of-order", event.seq, f"{kind} of {event.task_id} outside a task"
                )
            return
        task.last_seq = event.seq
        if kind == "plan_computed":
            plan = decode(event, PlanComputed)
            task.plans.append(dict(event.payload, seq=event.seq))
            order = " → ".join(k.split("/", 1)[1].split("|")[0] for k in plan.order) or "nothing"
            task.timeline.append(f"{event.seq}: plan {plan.room} ({plan.objective}): {order}")
        elif kind == "moved":
            moved = decode(event, Moved)
            task._moved_metres += moved.metres
            task.route.append(Point(moved.end.x, moved.end.y))
            task.timeline.append(
                f"{event.seq}: moved {moved.metres:.2f} m"
                + (" (stopped: target seen)" if moved.interrupted else "")
            )
        elif kind in ("view_taken", "container_opened"):
            # A view's event precedes its detections, so a view after the sighting is a new one.
            if task._target_seen_at is not None:
                self._not_acted_on(task, event.seq, f"went on to {kind.replace('_', ' ')}")
            if kind == "container_opened":
                what, static_id = "opened", decode(event, ContainerOpened).static_id
            else:
                view = decode(event, ViewTaken)
                what, static_id = f"looked ({view.reason}) at", view.static_id or "/nothing"
            task.timeline.append(f"{event.seq}: {what} {static_id.split('/', 1)[1]}")
        elif kind == "detection":
            detected = decode(event, Detected)
            if detected.accepted:
                support = detected.support if detected.support and detected.support.at else None
                where = "no static object" if support is None else support.static_class
                task.timeline.append(f"{event.seq}: saw {detected.object_class} at {where}")
                if support is not None:
                    learned = task.learned.setdefault(detected.object_class, [])
                    if support.static_class not in learned:
                        learned.append(support.static_class)
                if detected.object_class == task.target and task._target_seen_at is None:
                    task._target_seen_at = event.seq
        elif kind == "target_found":
            task._target_seen_at = None
            found = decode(event, TargetFound)
            task.found_at = Point(found.position[0], found.position[1])
            task.timeline.append(f"{event.seq}: found {found.instance_id}")
        elif kind == "search_failed":
            if task._target_seen_at is not None:
                self._not_acted_on(task, event.seq, "reported the search failed")
            task.timeline.append(
                f"{event.seq}: search failed — {decode(event, SearchFailed).reason}"
            )
        elif kind == "task_ended":
            self._task_ended(task, event)
        elif kind == "task_aborted":
            task.success = False
            aborted = decode(event, TaskAborted)
            task.path_length = aborted.path_length
            task.timeline.append(
                f"{event.seq}: task aborted ({aborted.reason}) after {task.path_length:.2f} m; "
                "nothing of it is folded into the scene graph"
            )
            self._finish(task)
            self._current = None

    def _task_started(self, event: Any) -> None:
        started = decode(event, TaskStarted)
        if self._current is not None:
            self._current.flag("out-of-order", event.seq, "a new task started before it ended")
            self._finish(self._current)
        run = self.state.run
        self._current = TaskAudit(
            task_id=str(event.task_id),
            target=started.target,
            start=started.start,
            home=run.home if run else "",
            first_seq=event.seq,
        )
        pose = self.state.pose
        if pose is not None:
            self._current.route.append(pose.point)
        self._current.timeline.append(
            f"{event.seq}: task started — find {started.target} from {started.start}"
        )

    def _task_ended(self, task: TaskAudit, event: Any) -> None:
        ended = decode(event, TaskEnded)
        task.success = ended.success
        task.path_length = ended.path_length
        if abs(task._moved_metres - task.path_length) > 1e-3:
            task.flag(
                "out-of-order",
                event.seq,
                f"task_ended says {task.path_length:.3f} m but its moves add up to "
                f"{task._moved_metres:.3f} m (a moved event is missing?)",
            )
        run = self.state.run
        mode = run.update_mode.value if run else "unknown"
        rule = "Eq. 4" if run is None or run.relations.model == "eq4" else run.relations.model
        task.updates.append(
            f"{rule} at seq {event.seq} (update mode {mode}): "
            + (
                "; ".join(f"{d} seen at {', '.join(s)}" for d, s in task.learned.items())
                or "nothing seen at a static object"
            )
        )
        task.timeline.append(
            f"{event.seq}: task ended — {'found' if task.success else 'not found'}, "
            f"{task.path_length:.2f} m"
        )
        self._finish(task)
        self._current = None

    def _finish(self, task: TaskAudit) -> None:
        self.tasks.append(task)
        if task.found_at is None or not task.home or not task.route:
            return
        ctx = load_context(task.home)
        room = ctx.navmap.room_at(task.found_at.x, task.found_at.y)
        goal = ctx.navmap.nearest_viewpoint(task.found_at.x, task.found_at.y, room)
        task.oracle_length = ctx.navmap.distance(task.route[0], goal)
        if (
            task.path_length is not None
            and task.path_length > self.oracle_ratio * task.oracle_length
            and task.path_length - task.oracle_length > self.oracle_excess_m
        ):
            task.flag(
                "far-above-oracle",
                task.last_seq,
                f"walked {task.path_length:.2f} m; straight to the object: "
                f"{task.oracle_length:.2f} m",
            )


#: What a report writes into its folder (an earlier report's are replaced).
REPORT_FILES = ("index.md", "task-*.md", "task-*.png", "index.html", "task-*.html")


def audit(
    events: Iterable[Any], *, models: RelationModels = AGENT_MODELS, **thresholds: float
) -> Auditor:
    auditor = Auditor(models=models, **thresholds)
    auditor.feed(events)
    return auditor


def write_report(
    auditor: Auditor,
    out: Path,
    *,
    plots: str = "flagged",
    max_plots: int | None = 25,
    title: str = "audit",
    html: Callable[[Auditor, Path], list[Path]] | None = None,
) -> list[Path]:
    """Markdown per task, an index, and route PNGs (``plots``: all, flagged or none; at most
    ``max_plots`` of them, in log order, since each takes a noticeable fraction of a second);
    ``html`` writes the web pages into the same claimed folder (``audit --html``)."""
    # An earlier report's pages must not mix with this one, so they go; nothing else in ``out`` is
    # touched, and a folder holding anything else where the report writes is refused.
    with claim(out, command="audit", owns=REPORT_FILES, replace_needs_force=False):
        written = _write_report(auditor, out, plots=plots, max_plots=max_plots, title=title)
        return written + (html(auditor, out) if html is not None else [])


def _write_report(
    auditor: Auditor, out: Path, *, plots: str, max_plots: int | None, title: str
) -> list[Path]:
    written: list[Path] = []
    rows = []
    plotted = 0
    for task in auditor.tasks:
        name = task.task_id.replace("(", "").replace(")", "").replace(" ", "-")
        png = None
        wanted = plots == "all" or (plots == "flagged" and bool(task.anomalies))
        if wanted and (max_plots is None or plotted < max_plots):
            plotted += 1
            png = out / f"{name}.png"
            if _plot_route(task, png):
                written.append(png)
            else:
                png = None
        md = out / f"{name}.md"
        md.write_text(_task_markdown(task, png))
        written.append(md)
        flags = ", ".join(sorted({a.kind for a in task.anomalies})) or "—"
        result = "found" if task.success else ("not found" if task.success is False else "?")
        ratio = (
            f"{task.path_length / task.oracle_length:.2f}"
            if task.path_length is not None and task.oracle_length
            else "—"
        )
        length = f"{task.path_length:.2f}" if task.path_length is not None else "—"
        rows.append(
            f"| [{task.task_id}]({md.name}) | {task.target} | {task.start} | {result} | "
            f"{length} | {ratio} | {flags} |"
        )
    counts = anomaly_counts(auditor.tasks)
    index = [
        f"# {title}",
        "",
        f"{len(auditor.tasks)} tasks; anomalies: "
        + (", ".join(f"{k} {v}" for k, v in sorted(counts.items())) or "none"),
        "",
        "| task | target | start | result | path (m) | ÷ oracle | anomalies |",
        "|---|---|---|---|---|---|---|",
        *rows,
        "",
    ]
    (out / "index.md").write_text("\n".join(index))
    written.append(out / "index.md")
    return written


def _task_markdown(task: TaskAudit, png: Path | None) -> str:
    lines = [f"# {task.task_id}: find {task.target} from {task.start}", ""]
    if task.path_length is not None:
        oracle = f"{task.oracle_length:.2f} m" if task.oracle_length is not None else "—"
        lines += [f"Path length {task.path_length:.2f} m; oracle {oracle}.", ""]
    if task.anomalies:
        lines += ["## Anomalies", ""]
        lines += [f"- **{a.kind}** (seq {a.seq}): {a.message}" for a in task.anomalies]
        lines.append("")
    if png is not None:
        lines += [f"![route]({png.name})", ""]
    lines += ["## Relation values behind each plan", ""]
    for plan in task.plans:
        lines.append(
            f"- seq {plan['seq']}, {plan['room']} (rooms left: {', '.join(plan['room_order'])}; "
            f"objective {plan['value']})"
        )
        for c in plan["candidates"]:
            rank = plan["order"].index(c["static_id"]) + 1
            name = c["static_id"].split("/", 1)[1]
            lines.append(f"  - #{rank} {name}: Rel = {float(c['rel']):.4f}")
    lines += ["", "## Experience and the update", ""]
    lines += [f"- {u}" for u in task.updates] or ["- (the task did not end)"]
    lines += ["", "## Timeline", "", *[f"- {t}" for t in task.timeline], ""]
    return "\n".join(lines)


def _plot_route(task: TaskAudit, path: Path) -> bool:
    """The task's route on the home's map, readable by someone who was not there: rooms and
    static objects named, stops numbered in travel order with arrows between them, a legend, and
    the figure cut to the home's extent."""
    if not task.home or len(task.route) < 2:
        return False
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch, Rectangle

    ctx = load_context(task.home)
    vps = list(ctx.navmap.room_of)
    xs = [p.x for p in vps] + [s.box.center[0] for s in ctx.semmap.statics]
    ys = [p.y for p in vps] + [s.box.center[1] for s in ctx.semmap.statics]
    margin = 0.6
    x0, x1, y0, y1 = min(xs) - margin, max(xs) + margin, min(ys) - margin, max(ys) + margin
    width = 12.0
    # The map's own aspect, plus room for the title and the legend below it.
    fig, ax = plt.subplots(figsize=(width, width * (y1 - y0) / (x1 - x0) + 1.6), dpi=100)
    ax.scatter([p.x for p in vps], [p.y for p in vps], s=2, c="#d0d0d0", zorder=1)
    for room in ctx.home.rooms:
        cx = sum(p.x for p in room.viewpoints) / len(room.viewpoints)
        cy = max(p.y for p in room.viewpoints) + 0.25
        ax.text(cx, cy, room.name, ha="center", va="bottom", fontsize=11, weight="bold",
                color="#444444", zorder=6)  # fmt: skip
    for s in ctx.semmap.statics:
        (cx, cy, _), (sx, sy, _) = s.box.center, s.box.size
        colour = "#1f77b4" if s.container else "#888888"
        ax.add_patch(
            Rectangle((cx - sx / 2, cy - sy / 2), sx, sy, fill=False, ec=colour, lw=0.8, zorder=2)
        )
        ax.text(cx, cy, s.cls, ha="center", va="center", fontsize=6, color=colour, zorder=2)
    for seg in _route_segments(ctx.navmap, task.route):
        ax.plot([p.x for p in seg], [p.y for p in seg], c="#d62728", lw=1.5, zorder=3)
        # An arrow on every other step shows the direction of travel.
        for u, v in list(itertools.pairwise(seg))[::2]:
            ax.annotate(
                "",
                xy=((u.x + v.x) / 2 + (v.x - u.x) * 0.15, (u.y + v.y) / 2 + (v.y - u.y) * 0.15),
                xytext=((u.x + v.x) / 2, (u.y + v.y) / 2),
                arrowprops={"arrowstyle": "-|>", "color": "#d62728", "lw": 1.0},
                zorder=3,
            )
    _draw_stops(ax, task.route)
    start = task.route[0]
    ax.scatter([start.x], [start.y], marker="o", s=70, c="green", ec="k", zorder=5)
    if task.found_at is not None:
        ax.scatter(
            [task.found_at.x], [task.found_at.y], marker="*", s=220, c="gold", ec="k", zorder=5
        )
    handles = [
        Line2D([], [], color="#d62728", lw=1.5, marker=">", label="route (arrows: direction)"),
        Line2D([], [], color="#d62728", lw=0, marker="o", ms=4, label="stop n (travel order)"),
        Line2D([], [], color="green", lw=0, marker="o", mec="k", ms=8, label=f"start ({task.start})"),
        Line2D([], [], color="gold", lw=0, marker="*", mec="k", ms=12,
               label=f"{task.target} found" if task.found_at else f"{task.target} not found"),
        Patch(fill=False, ec="#888888", label="static object"),
        Patch(fill=False, ec="#1f77b4", label="container (opened to look inside)"),
        Line2D([], [], color="#d0d0d0", lw=0, marker="o", ms=3, label="viewpoint (0.25 m grid)"),
    ]  # fmt: skip
    ax.legend(
        handles=handles,
        loc="upper center",
        bbox_to_anchor=(0.5, -0.16),
        ncol=4,
        fontsize=8,
        frameon=False,
    )
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    length = f", {task.path_length:.1f} m" if task.path_length is not None else ""
    ax.set_title(
        f"{task.task_id}: find {task.target} from {task.start}{length}, {len(task.route) - 1} stops"
    )
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    fig.savefig(path, bbox_inches="tight", pad_inches=0.1)
    plt.close(fig)
    return True


def _route_segments(navmap: Any, route: Sequence[Point]) -> list[list[Point]]:
    """Each move redrawn along the map's shortest path (what the robot walked, unless the map
    changed since); a teleport between doors starts a new line."""
    segments: list[list[Point]] = []
    current: list[Point] = []
    for a, b in itertools.pairwise(route):
        try:
            walk = navmap.path(a, b)
        except (ValueError, KeyError):
            walk = [a, b]
        for u, v in itertools.pairwise(walk):
            teleport = _is_teleport(navmap, u, v)
            if teleport or (current and current[-1] != u):
                if len(current) > 1:
                    segments.append(current)
                current = [v] if teleport else [u, v]
            else:
                current = [*current, v] if current else [u, v]
    if len(current) > 1:
        segments.append(current)
    return segments


def _draw_stops(ax: Any, route: Sequence[Point]) -> None:
    """Stops (where each move ended), numbered in travel order; a stop visited twice shows both."""
    labels: dict[Point, list[str]] = {}
    for i, p in enumerate(route[1:], start=1):
        labels.setdefault(p, []).append(str(i))
    for p, numbers in labels.items():
        ax.scatter([p.x], [p.y], s=16, c="#d62728", zorder=4)
        ax.annotate(
            ",".join(numbers),
            (p.x, p.y),
            xytext=(4, 4),
            textcoords="offset points",
            fontsize=7,
            color="#8b0000",
            bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8},
            zorder=7,
        )


def _is_teleport(navmap: Any, a: Point, b: Point) -> bool:
    return bool(navmap.has_edge(a, b) and navmap.is_teleport(a, b))


def anomaly_counts(tasks: Sequence[TaskAudit]) -> dict[str, int]:
    counts: dict[str, int] = {}
    for t in tasks:
        for a in t.anomalies:
            counts[a.kind] = counts.get(a.kind, 0) + 1
    return counts
