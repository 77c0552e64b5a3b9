"""Audit flags what went wrong in a task, and nothing in a clean run."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import msgspec
import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.outdir import claim
from objsearch.cli import main
from objsearch.events import Event, EventLog, read_log
from objsearch.replay.audit import REPORT_FILES, audit

LOG = Path(__file__).resolve().parent / "golden" / "sim-wpl-updates"


def _rewrite(events: Iterable[Event], out: Path) -> Path:
    """Write events (payloads possibly edited) as a fresh, valid log."""
    log = EventLog.open(out, "robot", store=STORE)
    try:
        for e in events:
            log.append(e.type, e.payload, time_ns=e.time_ns, task_id=e.task_id)
    finally:
        log.close()
    return out


def _kinds(log: Path) -> dict[str, set[str]]:
    found: dict[str, set[str]] = {}
    for task in audit(read_log(log, store=STORE)).tasks:
        for a in task.anomalies:
            found.setdefault(a.kind, set()).add(task.task_id)
    return found


def test_a_clean_run_has_no_integrity_anomalies() -> None:
    kinds = _kinds(LOG)
    assert not kinds.keys() & {"target-not-acted-on", "stale-plan", "out-of-order"}
    tasks = audit(read_log(LOG, store=STORE)).tasks
    assert len(tasks) == 8
    assert all(t.success and t.oracle_length is not None for t in tasks)
    assert all(
        t.path_length is not None
        and t.oracle_length is not None
        and t.path_length >= t.oracle_length - 1e-9
        for t in tasks
    )


def _task_found_by_looking() -> tuple[str, str, int]:
    """A task whose target turned up in a view, with the seq of an earlier view in that task."""
    events = list(read_log(LOG, store=STORE))
    for i, e in enumerate(events):
        if e.type != "target_found":
            continue
        views = [v for v in events[:i] if v.task_id == e.task_id and v.type == "view_taken"]
        if len(views) >= 2:
            target = next(x for x in events if x.task_id == e.task_id).payload["target"]
            return str(e.task_id), target, views[0].seq
    raise AssertionError("no task found its target after two views")


def _edited(log: Path, out: Path, edit: Callable[[Event], list[Event]]) -> Path:
    return _rewrite([x for e in read_log(log, store=STORE) for x in edit(e)], out)


def test_a_detection_the_robot_ignored_is_flagged(tmp_path: Path) -> None:
    task_id, target, view_seq = _task_found_by_looking()

    def inject(e: Event) -> list[Event]:
        if e.seq != view_seq:
            return [e]
        missed: dict[str, Any] = {
            "object_class": target,
            "instance_id": f"{target}|missed",
            "mask_area": 5000.0,
            "position": [0.0, 0.0, 0.0],
            "accepted": True,
            "support": None,
            "score": 1.0,
            "classes": [],
        }
        return [e, msgspec.structs.replace(e, type="detection", version=3, payload=missed)]

    kinds = _kinds(_edited(LOG, tmp_path / "log", inject))
    assert kinds.get("target-not-acted-on") == {task_id}


def test_a_plan_from_a_stale_scene_graph_is_flagged(tmp_path: Path) -> None:
    plans = [e for e in read_log(LOG, store=STORE) if e.type == "plan_computed"]
    victim = plans[len(plans) // 2]

    def stale(e: Event) -> list[Event]:
        if e.seq != victim.seq:
            return [e]
        cands = [dict(c) for c in e.payload["candidates"]]
        cands[0]["rel"] = min(1.0, float(cands[0]["rel"]) + 0.25)
        return [msgspec.structs.replace(e, payload={**e.payload, "candidates": cands})]

    kinds = _kinds(_edited(LOG, tmp_path / "log", stale))
    assert kinds.get("stale-plan") == {victim.task_id}


def test_a_missing_move_is_flagged(tmp_path: Path) -> None:
    moves = [e for e in read_log(LOG, store=STORE) if e.type == "moved" and e.payload["metres"] > 0]
    victim = moves[3]
    kinds = _kinds(_edited(LOG, tmp_path / "log", lambda e: [] if e.seq == victim.seq else [e]))
    assert kinds.get("out-of-order") == {victim.task_id}


def test_a_task_that_never_ended_is_flagged(tmp_path: Path) -> None:
    events = list(read_log(LOG, store=STORE))
    last_end = max(e.seq for e in events if e.type == "task_ended")
    log = _rewrite([e for e in events if e.seq < last_end], tmp_path / "log")
    tasks = audit(read_log(log, store=STORE)).tasks
    assert any(a.message.startswith("the task never ended") for a in tasks[-1].anomalies)


def test_far_above_oracle_uses_the_thresholds() -> None:
    strict = audit(read_log(LOG, store=STORE), oracle_ratio=1.0, oracle_excess_m=0.0).tasks
    lenient = audit(read_log(LOG, store=STORE), oracle_ratio=1e6, oracle_excess_m=1e6).tasks
    far = {t.task_id for t in strict if any(a.kind == "far-above-oracle" for a in t.anomalies)}
    assert far == {
        t.task_id
        for t in strict
        if t.path_length is not None
        and t.oracle_length is not None
        and t.path_length > t.oracle_length
    }
    assert not any(a.kind == "far-above-oracle" for t in lenient for a in t.anomalies)


def test_audit_writes_the_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report"
    with claim(out, command="audit", owns=REPORT_FILES, replace_needs_force=False):
        (out / "task-09999.md").write_text("stale page from an earlier report")
    (out / "notes.md").write_text("the analyst's own notes")
    assert main(["audit", str(LOG), "--out", str(out), "--plots", "all", "--max-plots", "2"]) == 0
    assert "8 tasks audited" in capsys.readouterr().out
    index = (out / "index.md").read_text()
    assert index.count("| [task-0") == 8
    assert len(list(out.glob("task-*.md"))) == 8
    assert len(list(out.glob("task-*.png"))) == 2
    page = (out / "task-00001.md").read_text()
    assert "## Relation values behind each plan" in page and "Eq. 4 at seq" in page
    assert not (out / "task-09999.md").exists()  # the earlier report's page went
    assert (out / "notes.md").read_text() == "the analyst's own notes"  # nothing else did


def test_audit_refuses_a_folder_it_did_not_write(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "thesis"
    out.mkdir()
    (out / "index.md").write_text("chapter 1")
    assert main(["audit", str(LOG), "--out", str(out), "--plots", "none"]) == 2
    assert "was not written by objsearch audit" in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == ["index.md"]
    assert (out / "index.md").read_text() == "chapter 1"


def test_route_png_is_cut_to_the_home_and_labelled(tmp_path: Path) -> None:
    """The PNG spans the home (not a fixed canvas ~40 % blank) and carries the names a reader
    needs: the test draws one and reads its text objects back through matplotlib's own hook."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.figure import Figure

    from objsearch.agent.session import load_context
    from objsearch.replay.audit import _plot_route, audit
    from objsearch.replay.source import open_events

    events, _ = open_events(LOG)
    task = next(t for t in audit(events).tasks if len(t.route) > 3)
    texts: list[str] = []
    original = Figure.savefig

    def keep_texts(fig: Figure, *args: object, **kwargs: object) -> None:
        for ax in fig.axes:
            texts.extend(t.get_text() for t in ax.texts)
            legend = ax.get_legend()
            if legend is not None:
                texts.extend(t.get_text() for t in legend.get_texts())
        original(fig, *args, **kwargs)  # type: ignore[arg-type]

    Figure.savefig = keep_texts  # type: ignore[method-assign, assignment]
    try:
        assert _plot_route(task, tmp_path / "route.png")
    finally:
        Figure.savefig = original  # type: ignore[method-assign]
    ctx = load_context(task.home)
    assert {r.name for r in ctx.home.rooms} <= set(texts)  # room names
    assert {s.cls for s in ctx.semmap.statics} <= set(texts)  # static object labels
    stops = len(task.route) - 1
    assert {str(i) for i in range(1, stops + 1)} <= {n for t in texts for n in t.split(",")}
    assert any(t.startswith("route") for t in texts) and any("start" in t for t in texts)
    pixels = np.asarray(plt.imread(tmp_path / "route.png"))[..., :3]
    blank_rows = float(np.mean((pixels > 0.98).all(axis=(1, 2))))
    assert blank_rows < 0.2, blank_rows
