"""Registering a new map to the working frame (agent/map_frames.py): the rigid fit from matched
statics, its refusals, and a world read through a transform."""

from __future__ import annotations

import math

import pytest

from objsearch.agent.errors import ObjsearchError
from objsearch.agent.geometry import Point, Pose
from objsearch.agent.map_frames import InFrame, Rigid2D, register
from objsearch.agent.session import load_context
from objsearch.sim.world import SimWorld


def test_a_transform_and_its_inverse_cancel() -> None:
    t = Rigid2D(2.1, -3.5, 4.25)
    back = t.inverse()
    for p in [(0.0, 0.0), (1.25, -7.5), (-3.0, 2.0)]:
        x, y = back.point(*t.point(*p))
        assert math.isclose(x, p[0], abs_tol=1e-12) and math.isclose(y, p[1], abs_tol=1e-12)
    moved = t.pose(Pose(1.0, 2.0, 0.5))
    assert math.isclose(moved.yaw, 0.5 + 2.1)
    # A quarter turn about the origin, then a shift: (1, 0) -> (0, 1) -> (10, 1).
    assert Rigid2D(math.pi / 2, 10.0, 0.0).point(1.0, 0.0) == pytest.approx((10.0, 1.0))


@pytest.mark.parametrize("frame", [Rigid2D(0.7, 3.0, -2.0), Rigid2D(-2.9, -4.5, 4.9)])
def test_registration_recovers_the_frame_from_the_statics(frame: Rigid2D) -> None:
    semmap = load_context("paper").semmap
    new = {s.id: (s.cls, Point(*frame.point(*s.box.center[:2]))) for s in semmap.statics}
    reg = register(semmap, new)
    expected = frame.inverse()
    assert reg.matched == len(semmap.statics)
    assert reg.rms_m < 1e-9
    assert math.isclose(
        math.remainder(reg.to_working.yaw - expected.yaw, math.tau), 0.0, abs_tol=1e-9
    )
    assert reg.to_working.x == pytest.approx(expected.x, abs=1e-9)
    assert reg.to_working.y == pytest.approx(expected.y, abs=1e-9)


def test_registration_matches_by_id_and_class_and_refuses_what_does_not_fit() -> None:
    semmap = load_context("paper").semmap
    frame = Rigid2D(1.0, 1.0, 1.0)
    new = {s.id: (s.cls, Point(*frame.point(*s.box.center[:2]))) for s in semmap.statics}
    # Only statics with the same id *and* class are paired.
    renamed = {k: ("NotAClass", p) for k, (_, p) in new.items()}
    with pytest.raises(ObjsearchError, match="0 of its statics match"):
        register(semmap, renamed)
    # Statics that moved between the maps (not a rigid motion): refused, not silently fitted.
    scrambled = dict(zip(new, [(c, Point(p.y * 3, -p.x)) for c, p in new.values()], strict=True))
    with pytest.raises(ObjsearchError, match="RMS"):
        register(semmap, scrambled)


def test_a_world_read_through_a_transform_and_back_is_the_world() -> None:
    ctx = load_context("paper")
    start = ctx.home.start("kitchen-1")
    frame = Rigid2D(2.3, -1.5, 3.75)

    def world() -> SimWorld:
        return SimWorld(ctx.home, ctx.navmap, {}, start)

    plain = world()
    moved = InFrame(world(), frame, inner=ctx.navmap)
    # The moved world reports in the new frame: its pose is the plain one's, transformed.
    assert moved.pose() == pytest.approx(frame.pose(plain.pose()))
    assert moved.pose().point not in ctx.navmap.room_of
    # Read back through the inverse (what registration gives), every point is a viewpoint again.
    back = InFrame(moved, frame.inverse(), outer=ctx.navmap)
    assert back.pose().point == plain.pose().point
    goal = max(ctx.navmap.viewpoints(ctx.navmap.room_at(start.x, start.y)))
    a, b = plain.navigate(goal), back.navigate(goal)
    assert b.path == a.path and b.end.point == a.end.point and b.metres == a.metres
    assert b.end.yaw == pytest.approx(a.end.yaw)
