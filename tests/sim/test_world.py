"""The simulated world: motion, the camera model and closed containers."""

from __future__ import annotations

import math

import pytest

from objsearch.agent.geometry import Pose
from objsearch.agent.home import Box
from objsearch.agent.session import load_context
from objsearch.sim.longterm import scenes_of
from objsearch.sim.perception import Camera
from objsearch.sim.placements import Placement, Schedule, base_placements
from objsearch.sim.world import (
    OPEN_S,
    SPEED_M_PER_S,
    FirstSighting,
    SimClock,
    SimWorld,
    first_sighting,
    mask_facing,
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


@pytest.mark.parametrize(
    ("home", "scene", "start"),
    [
        ("paper", None, "bedroom-1"),
        ("paper", None, "kitchen-1"),
        # The robot starts on the viewpoint nearest a vase that it cannot see from there: the
        # oracle steps away to see it and comes back (1.0 m, not 0).
        ("paper", 8, "bathroom-2"),
    ],
)
def test_oracle_walks_to_where_it_sees_the_target_then_approaches_it(
    home: str, scene: int | None, start: str
) -> None:
    # Measured like a search's full path: to a viewpoint that detects it, then to the viewpoint
    # nearest it (where a search's approach ends); the shortest such walk over every viewpoint,
    # for every class placed.
    ctx = load_context(home)
    placements = base_placements(ctx.home) if scene is None else scenes_of(home, "stats-0")[scene]
    world = SimWorld(ctx.home, ctx.navmap, placements, ctx.home.start(start))
    here = world.pose().point
    detours = 0
    for cls in sorted({p.cls for p in world.placements.values()}):
        threshold = ctx.vocabulary.classes[cls].min_mask_area_px
        oracle = world.oracle_length(cls, min_mask_px=threshold)
        walks = []
        for p in (p for p in world.placements.values() if p.cls == cls):
            end = ctx.navmap.nearest_viewpoint(p.box.center[0], p.box.center[1], p.room)
            placed = [q for q in world.placements.values() if q.room == p.room]
            for v in ctx.navmap.viewpoints(p.room):
                # Facing it, camera pitched at it, its container opened (tests/sim/
                # test_visibility.py holds mask_facing's camera to the full render).
                if mask_facing(world.camera, ctx.home, v, p, placed) >= threshold:
                    walks.append(ctx.navmap.distance(here, v) + ctx.navmap.distance(v, end))
        straight = min(
            ctx.navmap.distance(here, ctx.navmap.nearest_viewpoint(*p.box.center[:2], p.room))
            for p in world.placements.values()
            if p.cls == cls
        )
        # With no detecting viewpoint, the walk to the approach viewpoint.
        assert oracle == pytest.approx(min(walks) if walks else straight, abs=1e-9), cls
        assert oracle >= straight - 1e-9  # never shorter than walking straight to the approach
        detours += oracle > straight + 1e-9
    assert detours == (scene is not None)  # the case above was met
    with pytest.raises(ValueError, match="no Spoon"):
        world.oracle_length("Spoon", min_mask_px=1.0)


def test_first_sighting_stops_at_the_first_viewpoint_that_detects() -> None:
    ctx = load_context("paper")
    world = _world()
    camera = world.camera
    for cls in ("Apple", "Pillow"):
        p = next(p for p in world.placements.values() if p.cls == cls)
        placed = [q for q in world.placements.values() if q.room == p.room]
        threshold = ctx.vocabulary.classes[cls].min_mask_area_px
        order = sorted(ctx.navmap.viewpoints(p.room), key=lambda v: (-v.x, v.y))
        areas = {v: mask_facing(camera, ctx.home, v, p, placed) for v in order}
        first = next(v for v in order if areas[v] >= threshold)
        found = first_sighting(camera, ctx.home, p, placed, order, threshold)
        assert found == FirstSighting(first, areas[first])
        blind = [v for v in order if areas[v] < threshold]
        missed = first_sighting(camera, ctx.home, p, placed, blind, threshold)
        assert missed == FirstSighting(None, max(areas[v] for v in blind))


def test_a_start_off_the_grid_is_refused() -> None:
    ctx = load_context("paper")
    with pytest.raises(ValueError, match="not a viewpoint"):
        SimWorld(ctx.home, ctx.navmap, {}, Pose(-50.0, -50.0, 0.0))
