"""Inspection ``cover``: the stretches of a long static that a second pass looks at."""

from __future__ import annotations

from objsearch.agent.geometry import Pose, heading
from objsearch.agent.policy import COVER_SPAN_M, cover_points, static_pitch
from objsearch.agent.session import load_context
from objsearch.sim.longterm import scenes_of
from objsearch.sim.world import first_sighting, search_camera


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


def test_the_phone_its_worktops_viewpoint_misses_is_seen_from_a_stretch_of_the_grid() -> None:
    """procthor-03, habit-1, scene 13: every strategy failed there, ``cover`` too while it looked
    only along the worktop's long side (protocol v4)."""
    ctx = load_context("procthor-03")
    placed = scenes_of("procthor-03", "habit-1", upto=13)[13]
    phone = next(p for p in placed.values() if p.cls == "Phone")
    room = [p for p in placed.values() if p.room == phone.room]
    worktop = next(s for s in ctx.semmap.statics if s.id == phone.support)
    threshold = ctx.vocabulary.classes["Phone"].min_mask_area_px
    camera = search_camera("geometric")
    at_stop = first_sighting(camera, ctx.home, phone, room, [worktop.viewpoint], threshold)
    assert at_stop.viewpoint is None  # N_s sees too little of it, facing it straight

    def mask_from(stretch_index: int) -> float:
        point = cover_points(worktop)[stretch_index]
        vp = ctx.navmap.nearest_viewpoint(point.x, point.y, worktop.room)
        pose = Pose(vp.x, vp.y, heading(vp, point))
        pitch = static_pitch(vp, worktop)
        seen = camera.detections(ctx.home, phone.room, pose, pitch, room, (phone,), None)
        return max((d.mask_area for d in seen), default=0.0)

    assert max(mask_from(k) for k in range(len(cover_points(worktop)))) >= threshold
