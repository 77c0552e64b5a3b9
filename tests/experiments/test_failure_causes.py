"""Why a search failed (experiments/report_homes.py failure_cause), read with the inspection's views."""

from __future__ import annotations

from dataclasses import replace

from objsearch.agent.session import load_context
from objsearch.agent.stops import cover_views
from objsearch.experiments.report_homes import failure_cause
from objsearch.experiments.runner import Row
from objsearch.sim.longterm import scenes_of


def test_a_phone_its_worktops_viewpoint_misses_is_seen_from_a_stretch_of_the_grid() -> None:
    """procthor-03, habit-1, scene 13: every strategy failed there, ``cover`` too while it looked
    only along the worktop's long side (protocol v4); the failure's cause says which view sees it."""
    placed = scenes_of("procthor-03", "habit-1", upto=13)[13]
    phone = next(p for p in placed.values() if p.cls == "Phone")
    ctx = load_context("procthor-03")
    worktop = next(s for s in ctx.semmap.statics if s.id == phone.support)
    views = cover_views(ctx.navmap, worktop.viewpoint, [worktop])
    assert len(views) >= 2 and all(v.viewpoint != worktop.viewpoint for v in views)
    failed = Row(
        "homes", "procthor-03", "habit-1", "global-belief", "all", 1, 13, "Phone", "x",
        False, 0.0, 0.0, "task-1",
    )  # fmt: skip
    single = failure_cause(failed, "geometric")
    assert "not from the viewpoint its static is inspected from" in single
    assert "cover" not in single
    covered = failure_cause(replace(failed, strategy="global-belief+cover"), "geometric")
    assert covered.startswith(single)
    assert "a stretch inspection cover looks at shows" in covered
