"""Inspection ``cover``: the stretches of a long static that a second pass looks at."""

from __future__ import annotations

from objsearch.agent.session import load_context
from objsearch.agent.stops import COVER_SPAN_M, cover_points


def test_a_worktop_long_both_ways_is_covered_by_a_grid_and_a_short_static_not_at_all() -> None:
    ctx = load_context("procthor-03")
    statics = {s.id: s for s in ctx.semmap.statics}
    worktop = statics["kitchen/CountertopLx|6|1"]  # an L: its box is 3.05 m by 2.44 m
    points = cover_points(worktop)
    assert len(points) == 3 * 2
    (cx, cy, _), (sx, sy, _) = worktop.box.center, worktop.box.size
    assert all(abs(p.x - cx) < sx / 2 and abs(p.y - cy) < sy / 2 for p in points)
    short = [s for s in statics.values() if max(s.box.size[0], s.box.size[1]) <= COVER_SPAN_M]
    assert short and all(cover_points(s) == [] for s in short)
