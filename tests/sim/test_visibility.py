"""The occluding search camera against the full render, and against the geometric camera."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from objsearch.agent.camera_frames import DEFAULT_INTRINSICS, MAX_PITCH, camera_to_map, project
from objsearch.agent.geometry import Pose
from objsearch.agent.session import load_context
from objsearch.sim.placements import Placement, base_placements
from objsearch.sim.render import render, room_scene
from objsearch.sim.visibility import OccludingCamera, VisibilityCache, mask_areas
from objsearch.sim.world import facing_view, search_camera

HOMES = ("paper", "ithor-02", "procthor-02")
POSES_PER_HOME = 100


@pytest.mark.parametrize("home", HOMES)
def test_mask_areas_are_the_full_renders_pixel_counts(home: str) -> None:
    # Random viewpoints, yaws and tilts over the tilt unit's range; half the views of a room with
    # containers with one opened. Every object of the room, statics included, is counted: exactly.
    ctx = load_context(home)
    placements = base_placements(ctx.home)
    rng = random.Random(f"visibility:{home}")
    opened_views = tilted = seen = 0
    for _ in range(POSES_PER_HOME):
        room = rng.choice(ctx.home.rooms)
        v = rng.choice(ctx.navmap.viewpoints(room.name))
        pitch = rng.choice((0.0, rng.uniform(0.0, MAX_PITCH)))
        t = camera_to_map(Pose(v.x, v.y, rng.uniform(-math.pi, math.pi)), pitch=pitch)
        scene = room_scene(ctx.home, room, placements.values())
        containers = [s.id for s in room.statics if s.container]
        if containers and rng.random() < 1 / 2:
            scene = scene.without(rng.choice(containers))
            opened_views += 1
        tilted += pitch > 0
        instance = render(scene, DEFAULT_INTRINSICS, t).instance
        counts = np.bincount(instance[instance >= 0].ravel(), minlength=len(scene.objects))
        areas = mask_areas(scene, [o.id for o in scene.objects], t)
        assert areas == {o.id: int(counts[k]) for k, o in enumerate(scene.objects)}
        seen += sum(a > 0 for a in areas.values())
    assert opened_views >= 5 and tilted > 30 and seen > POSES_PER_HOME  # the cases were met


def _behind_a_static() -> tuple[str, Placement, Pose, float, float]:
    """The first (placement, viewpoint) of the paper home, in a fixed order, from which the
    geometric camera detects the object and the occluding camera sees none of it, with no other
    object placed in the room (so only statics can hide it)."""
    ctx = load_context("paper")
    placements = base_placements(ctx.home)
    geometric, occluding = search_camera("geometric"), search_camera("occluding")
    for p in sorted(placements.values(), key=lambda p: p.instance_id):
        if p.inside:
            continue
        threshold = ctx.vocabulary.classes[p.cls].min_mask_area_px
        for v in ctx.navmap.viewpoints(p.room):
            pose, pitch = facing_view(v, p.box.center)
            args = (ctx.home, p.room, pose, pitch, (p,), (p,), None)
            geo = geometric.detections(*args)
            if geo and geo[0].mask_area >= threshold and not occluding.detections(*args):
                return p.room, p, pose, pitch, geo[0].mask_area
    raise AssertionError("no placement of the paper home is hidden behind a static")


def test_a_target_behind_a_static_is_detected_by_the_geometric_camera_only() -> None:
    ctx = load_context("paper")
    room, target, pose, pitch, _ = _behind_a_static()
    # What stands between: the render shows a static where the target's centre projects, nearer
    # than the target.
    scene = room_scene(ctx.home, room, [target])
    t = camera_to_map(pose, pitch=pitch)
    out = render(scene, DEFAULT_INTRINSICS, t)
    ((u, v),), (z,) = project(
        np.array([target.box.center], dtype=np.float32), DEFAULT_INTRINSICS, t
    )
    shown = scene.objects[int(out.instance[round(float(v)), round(float(u))])]
    assert shown.id in {s.id for s in ctx.home.room(room).statics}
    assert 0 < out.depth[round(float(v)), round(float(u))] < z


def test_views_are_cached_and_the_cache_is_bounded() -> None:
    ctx = load_context("paper")
    placements = base_placements(ctx.home)
    placed = sorted(
        (p for p in placements.values() if p.room == "kitchen"), key=lambda p: p.instance_id
    )
    cache = VisibilityCache(max_views=2)
    camera = OccludingCamera(cache=cache)
    poses = [Pose(v.x, v.y, 0.5) for v in ctx.navmap.viewpoints("kitchen")[:3]]
    first = camera.areas(ctx.home, "kitchen", poses[0], 0.2, placed, None)
    assert camera.areas(ctx.home, "kitchen", poses[0], 0.2, placed, None) == first
    assert (cache.hits, cache.misses) == (1, 1)
    # Another tilt, another opened container or other placements are other views.
    camera.areas(ctx.home, "kitchen", poses[0], 0.3, placed, None)
    camera.areas(ctx.home, "kitchen", poses[1], 0.2, placed, None)  # evicts the first view
    assert (cache.hits, cache.misses) == (1, 3)
    camera.areas(ctx.home, "kitchen", poses[0], 0.2, placed, None)
    assert (cache.hits, cache.misses) == (1, 4)
