"""`objsearch replay` and `objsearch audit`: explain and re-check what a robot decided."""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

from objsearch import cli_types as t


def register(sub: Any) -> None:
    rp = sub.add_parser(
        "replay",
        help="re-run every recorded plan with today's code on the inputs the robot had",
        description="Folds the log up to each plan_computed event (scene graph, run settings, "
        "task, pose) and plans again with today's code. Exit status 0 when every decision is "
        "the same, 1 when any differs.",
    )
    rp.add_argument(
        "log",
        metavar="LOG|LAKE",
        type=t.log_or_lake,
        help="event log folder, or a lake (with --run): a folder or s3://bucket/prefix",
    )
    rp.add_argument(
        "--run", type=t.text, help="the lake run to replay (objsearch lake ls lists them)"
    )
    rp.add_argument("--robot", type=t.text, help="the robot whose run it is, if run names repeat")
    rp.add_argument("--until", type=t.int_range(0), metavar="SEQ", help="stop after this event")
    rp.add_argument("--alpha", type=t.ALPHA, help="replay with another alpha (Eq. 3), 0-1000")
    rp.add_argument("--method", choices=["wpl", "rvp", "sdp"], help="replay with another method")
    rp.add_argument(
        "--strategy",
        type=t.strategy,
        help="replay with another strategy, NAME or NAME+cover (e.g. epl, wpl-neg-decay)",
    )
    t.format_option(rp, "print every decision as JSON")
    rp.add_argument("--all", action="store_true", help="list unchanged decisions too")
    t.progress_option(rp)
    rp.set_defaults(func=cmd_replay)

    au = sub.add_parser(
        "audit",
        help="a per-task report: timeline, route, relation values, anomalies",
        description="Writes index.md and one Markdown file per task (with a route PNG for "
        "flagged tasks, or all with --plots all) to --out; with --html also index.html and a "
        "self-contained page per task.",
    )
    au.add_argument(
        "log",
        metavar="LOG|LAKE",
        type=t.log_or_lake,
        help="event log folder, or a lake (with --run): a folder or s3://bucket/prefix",
    )
    au.add_argument("--run", type=t.text, help="the lake run to audit")
    au.add_argument("--robot", type=t.text, help="the robot whose run it is, if run names repeat")
    au.add_argument(
        "--out",
        default="out/audit",
        type=t.dir_path,
        help="report folder (out/audit); an earlier report there is replaced, a folder holding "
        "anything else where the report writes is refused",
    )
    au.add_argument("--plots", choices=["all", "flagged", "none"], default="flagged")
    au.add_argument(
        "--max-plots",
        type=t.int_range(0, 10_000),
        default=25,
        help="at most this many PNGs, 0-10000 (25)",
    )
    au.add_argument(
        "--oracle-ratio",
        type=t.float_range(1.0, 1e6),
        default=5.0,
        help="flag a task whose path exceeds this many times the oracle (5; at least 1) ...",
    )
    au.add_argument(
        "--oracle-excess",
        type=t.float_range(0.0, 1e6),
        default=10.0,
        help="... and the oracle by this many m (10)",
    )
    t.format_option(au, "print the anomalies as JSON")
    au.add_argument(
        "--html",
        action="store_true",
        help="also write index.html and a page per task (sortable tables, inline SVG routes "
        "for the tasks --plots names), self-contained: open index.html from disk",
    )
    t.progress_option(au)
    au.set_defaults(func=cmd_audit)


def cmd_replay(args: argparse.Namespace) -> int:
    from objsearch.product import relation_models
    from objsearch.replay.decisions import Overrides, replay, summarise
    from objsearch.replay.source import open_events

    events, _ = open_events(args.log, run=args.run, robot=args.robot)
    replayer = replay(
        t.progress(events, "replay", " events", enabled=not args.no_progress),
        overrides=Overrides(method=args.method, alpha=args.alpha, strategy=args.strategy),
        until_seq=args.until,
        models=relation_models(simulator=True),
    )
    decisions = replayer.decisions
    summary = summarise(decisions)
    if args.format == "json":
        shown = decisions if args.all else [d for d in decisions if not d.same]
        doc = {**summary, "notes": replayer.notes, "decisions": [d.as_dict() for d in shown]}
        print(json.dumps(doc, indent=2))
    else:
        for note in replayer.notes:
            print(f"note: {note}")
        for d in decisions:
            if d.same and not args.all:
                continue
            status = "same" if d.same else "DIFFERENT"
            parts = []
            if not d.same_rooms:
                parts.append(f"rooms {list(d.recorded_rooms)} → {list(d.replayed_rooms)}")
            if not d.same_order:
                parts.append(f"order {_short(d.recorded_order)} → {_short(d.replayed_order)}")
            print(
                f"seq {d.seq} {d.task_id} {d.target} in {d.room}: {status}; objective recorded "
                f"{d.recorded_value:.4f}, recorded order today {d.recorded_value_today:.4f}, "
                f"replayed {d.replayed_value:.4f}"
            )
            for part in parts:
                print(f"    {part}")
            for reason in d.reasons:
                print(f"    because {reason}")
        print(
            f"{summary['decisions']} decisions: {summary['same']} same, "
            f"{summary['different_room_order']} with another room order, "
            f"{summary['different_object_order']} with another object order"
        )
    return 0 if summary["same"] == summary["decisions"] else 1


def _short(order: tuple[str, ...]) -> str:
    """``kitchen/Shelf|+01.31|+00.97|-02.30`` → ``Shelf(+01.31,-02.30)`` (AI2-THOR x, z)."""
    names = []
    for key in order:
        parts = key.split("/", 1)[-1].split("|")
        names.append(f"{parts[0]}({parts[1]},{parts[3]})" if len(parts) >= 4 else parts[0])
    return "[" + ", ".join(names) + "]"


#: Events that end a task: what ``audit`` counts for its lines in a pipe.
TASK_END_EVENTS = frozenset({"task_ended", "task_aborted"})
#: Tasks between two of ``audit``'s lines in a pipe (a demo log holds 1,280).
AUDIT_LINE_EVERY = 100


def cmd_audit(args: argparse.Namespace) -> int:
    from objsearch.product import relation_models
    from objsearch.replay.audit import anomaly_counts, audit, write_report
    from objsearch.replay.source import open_events

    events, name = open_events(args.log, run=args.run, robot=args.robot)
    shown = not args.no_progress
    # A terminal gets the bar; a pipe or a log a line per AUDIT_LINE_EVERY tasks read.
    tasks = t.log_lines(
        t.progress(events, "audit", " events", enabled=shown),
        "audit",
        "tasks",
        counts=lambda event: event.type in TASK_END_EVENTS,
        every=AUDIT_LINE_EVERY,
        enabled=shown,
    )
    auditor = audit(
        tasks,
        oracle_ratio=args.oracle_ratio,
        oracle_excess_m=args.oracle_excess,
        models=relation_models(simulator=True),
    )
    out = Path(args.out)
    title = f"audit of {name}"
    html: Callable[[Any, Path], list[Path]] | None = None
    if args.html:
        from objsearch.experiments.report_html import write_audit_html

        html = partial(write_audit_html, plots=args.plots, max_plots=args.max_plots, title=title)

    t.log_line(f"audit: writing the report of {len(auditor.tasks)} tasks to {out}", enabled=shown)
    write_report(auditor, out, plots=args.plots, max_plots=args.max_plots, title=title, html=html)
    counts = anomaly_counts(auditor.tasks)
    if args.format == "json":
        anomalies = [
            {"task_id": t.task_id, "kind": a.kind, "seq": a.seq, "message": a.message}
            for t in auditor.tasks
            for a in t.anomalies
        ]
        print(json.dumps({"tasks": len(auditor.tasks), "anomalies": anomalies}, indent=2))
    else:
        print(
            f"{len(auditor.tasks)} tasks audited; anomalies: "
            + (", ".join(f"{k} {v}" for k, v in sorted(counts.items())) or "none")
        )
        print(f"report: {out / 'index.md'}" + (f", {out / 'index.html'}" if args.html else ""))
    return 0
