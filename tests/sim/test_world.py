"""The simulated world: motion, the camera model and closed containers."""

from __future__ import annotations

import math

import pytest

from objsearch.agent.geometry import Pose
from objsearch.agent.home import Box
from objsearch.agent.session import load_context
from objsearch.sim.perception import Camera
from objsearch.sim.placements import Schedule, base_placements
from objsearch.sim.world import (
    OPEN_S,
    SPEED_M_PER_S,
    Placement,
    SimClock,
    SimWorld,
    facing_view,
)


def _world(start: str = "kitchen-1", placements: dict[str, Placement] | None = None) -> SimWorld:
    ctx = load_context("paper")
    return SimWorld(
        ctx.home,
        ctx.navmap,
        base_placements(ctx.home) if placements is None else placements,
        ctx.home.start(start),
    )


def test_navigation_walks_the_shortest_path_and_takes_time() -> None:
    world = _world()
    ctx = load_context("paper")
    goal = ctx.navmap.viewpoints("kitchen")[-1]
    expected = ctx.navmap.distance(world.pose().point, goal)
    nav = world.navigate(goal)
    assert nav.metres == pytest.approx(expected)
    assert world.pose().point == goal
    assert world.now_ns() == pytest.approx(expected / SPEED_M_PER_S * 1e9, abs=10)


def test_room_changes_teleport_at_the_doors_without_metres() -> None:
    world = _world("kitchen-1")
    ctx = load_context("paper")
    door_k, door_b = ctx.navmap.doors["kitchen"], ctx.navmap.doors["bathroom"]
    nav = world.navigate(door_b)
    assert nav.rooms == ("kitchen", "bathroom")
    assert nav.metres == pytest.approx(
        ctx.navmap.distance(ctx.home.start("kitchen-1").point, door_k)
    )


def test_camera_sees_only_within_its_field_of_view() -> None:
    cam = Camera()
    box = Box((2.0, 0.0, 1.0), (0.2, 0.2, 0.2))
    assert cam.in_view(Pose(0.0, 0.0, 0.0), box)
    assert cam.in_view(Pose(0.0, 0.0, math.radians(44)), box)
    assert not cam.in_view(Pose(0.0, 0.0, math.radians(46)), box)
    assert not cam.in_view(Pose(0.0, 0.0, math.pi), box)
    # The 0.2 m cube at 2 m, seen with f = 320 px: 32 × 32 px.
    assert cam.mask_area(Pose(0.0, 0.0, 0.0), box) == pytest.approx(32 * 32)
    assert cam.mask_area(Pose(1.0, 0.0, 0.0), box) == pytest.approx(64 * 64)


def test_a_flat_object_seen_from_above_shows_its_top() -> None:
    # A phone (0.15 × 0.08 × 0.01 m) lying on a bed 1.5 m away, camera 0.5 m above it: its edge
    # alone is ~30 px, under the 100 px threshold; with its top face (what a camera sees) it is
    # well above. Straight on, at the camera's height, only the edge shows.
    cam = Camera()
    phone = Box((1.5, 0.0, 0.5), (0.15, 0.08, 0.01))
    d = math.hypot(1.5, 0.5)
    edge = 320**2 * (0.08 * 0.01 * 1.5 / d) / d**2
    top = 320**2 * (0.15 * 0.08 * 0.5 / d) / d**2
    assert cam.mask_area(Pose(0.0, 0.0, 0.0), phone) == pytest.approx(edge + top)
    assert cam.mask_area(Pose(0.0, 0.0, 0.0), phone) > 100 > edge
    level = Box((1.5, 0.0, 1.0), (0.15, 0.08, 0.01))
    assert cam.mask_area(Pose(0.0, 0.0, 0.0), level) == pytest.approx(320**2 * 0.08 * 0.01 / 1.5**2)


def test_a_closed_container_hides_its_contents_until_opened() -> None:
    ctx = load_context("paper")
    schedule = Schedule.load(ctx.home, "table2")
    scene, placed = next(
        (n, p)
        for n, placements in sorted(schedule.scenes.items())
        for p in placements.values()
        if p.inside and p.support is not None and ctx.home.statics[p.support].cls == "Fridge"
    )
    fridge = next(s for s in ctx.semmap.statics if s.id == placed.support)
    world = SimWorld(
        ctx.home,
        ctx.navmap,
        schedule.scenes[scene],
        Pose(fridge.viewpoint.x, fridge.viewpoint.y, 0.0),
        clock=SimClock(),
    )
    seen_closed = {d.instance_id for d in world.look(fridge.view_yaw)}
    assert placed.instance_id not in seen_closed
    before = world.now_ns()
    seen_open = {d.instance_id for d in world.open(fridge.id)}
    assert placed.instance_id in seen_open
    assert world.now_ns() - before == pytest.approx(OPEN_S * 1e9)


def test_opening_what_is_not_a_container_is_refused() -> None:
    ctx = load_context("paper")
    world = _world()
    sink = next(s for s in ctx.semmap.statics if s.cls == "Sink")
    with pytest.raises(ValueError, match="not a container"):
        world.open(sink.id)


def test_oracle_walks_to_where_it_sees_the_target_then_approaches_it() -> None:
    # Measured like a search's full path: to a viewpoint that detects it, then to the viewpoint
    # nearest it (where a search's approach ends); the shortest such walk over every viewpoint.
    world = _world("bedroom-1")
    ctx = load_context("paper")
    threshold = ctx.vocabulary.classes["Pillow"].min_mask_area_px
    oracle = world.oracle_length("Pillow", min_mask_px=threshold)
    here = world.pose().point
    walks = []
    for p in (p for p in world.placements.values() if p.cls == "Pillow"):
        end = ctx.navmap.nearest_viewpoint(p.box.center[0], p.box.center[1], p.room)
        for v in ctx.navmap.viewpoints(p.room):
            # What the robot sees standing there, facing the pillow, camera pitched at it.
            pose, pitch = facing_view(v, p.box.center)
            probe = SimWorld(ctx.home, ctx.navmap, world.placements, pose)
            seen = probe.look(pose.yaw, pitch)
            mask = max((d.mask_area for d in seen if d.instance_id == p.instance_id), default=0.0)
            if mask >= threshold:
                walks.append(ctx.navmap.distance(here, v) + ctx.navmap.distance(v, end))
    assert walks and oracle == pytest.approx(min(walks))
    # Never shorter than walking straight to the approach viewpoint.
    straight = min(
        ctx.navmap.distance(here, ctx.navmap.nearest_viewpoint(*p.box.center[:2], p.room))
        for p in world.placements.values()
        if p.cls == "Pillow"
    )
    assert oracle >= straight - 1e-9
    with pytest.raises(ValueError, match="no Spoon"):
        world.oracle_length("Spoon", min_mask_px=threshold)


def test_a_start_off_the_grid_is_refused() -> None:
    ctx = load_context("paper")
    with pytest.raises(ValueError, match="not a viewpoint"):
        SimWorld(ctx.home, ctx.navmap, {}, Pose(-50.0, -50.0, 0.0))
