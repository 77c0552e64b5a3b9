"""The semantic map: loc_s, N_s, θ_s and how they compare with ALFRED's interaction poses."""

from __future__ import annotations

import math

import pytest

from objsearch.agent.geometry import wrap_angle
from objsearch.agent.semmap import compare_with_alfred
from objsearch.agent.session import load_context


def test_every_static_has_its_rooms_nearest_viewpoint_facing_it() -> None:
    ctx = load_context("paper")
    assert len(ctx.semmap.statics) == sum(len(r.statics) for r in ctx.home.rooms)
    for s in ctx.semmap.statics:
        vps = ctx.navmap.viewpoints(s.room)
        best = min(math.hypot(p.x - s.loc.x, p.y - s.loc.y) for p in vps)
        assert math.hypot(s.viewpoint.x - s.loc.x, s.viewpoint.y - s.loc.y) == best
        facing = math.atan2(s.loc.y - s.viewpoint.y, s.loc.x - s.viewpoint.x)
        assert abs(wrap_angle(s.view_yaw - facing)) < 1e-9


def test_semantic_map_lookup_finds_the_supporting_static() -> None:
    ctx = load_context("paper")
    bed = next(s for s in ctx.semmap.statics if s.cls == "Bed")
    on_the_bed = (bed.box.center[0], bed.box.center[1], bed.box.top + 0.05)
    nearest = ctx.semmap.nearest(on_the_bed, bed.room)
    assert nearest is not None
    assert nearest[0].id == bed.id
    assert nearest[1] == pytest.approx(0.05)


def test_our_viewpoints_agree_with_alfred_interaction_poses() -> None:
    """ALFRED's poses are where a planner put the agent to interact; ours are the nearest
    viewpoint. Most should be within a metre and face the same way within 45°."""
    ctx = load_context("paper")
    agreement = compare_with_alfred(ctx.home, ctx.semmap)
    assert agreement.matched >= 20
    assert agreement.fraction_within(1.0) >= 0.85
    assert agreement.yaw_fraction_within(math.pi / 4) >= 0.75
    summary = agreement.summary()
    assert summary["matched"] == agreement.matched
