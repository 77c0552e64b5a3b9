"""The paper home: geometry rules checked against the raw scenes they come from."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path
from typing import Any

import pytest

from objsearch.pipeline.build import PAPER_HOME
from objsearch.pipeline.geometry import RoomFrame
from objsearch.pipeline.rooms import obstacle_footprints
from objsearch.pipeline.sources import load_scene

ROOMS = ("kitchen", "living", "bedroom", "bathroom")
TYPES = ("Kitchen", "LivingRoom", "Bedroom", "Bathroom")


def rooms(home: dict[str, Any]) -> list[dict[str, Any]]:
    return list(home["rooms"])


def test_rooms_are_in_order_and_laid_out_along_x(home: dict[str, Any]) -> None:
    rs = rooms(home)
    assert [r["name"] for r in rs] == list(ROOMS)
    assert [r["room_type"] for r in rs] == list(TYPES)
    assert [r["source_scene"] for r in rs] == list(PAPER_HOME)
    assert rs[0]["extent"]["min"][0] == pytest.approx(0.0, abs=1e-9)
    for prev, room in itertools.pairwise(rs):
        gap = room["extent"]["min"][0] - prev["extent"]["max"][0]
        assert 1.0 - 1e-4 <= gap < 1.25
    for room in rs:
        assert 0.0 - 1e-4 <= room["extent"]["min"][1] < 0.25
        assert all(v / 0.25 == round(v / 0.25) for v in room["offset"])


def test_viewpoints_lie_on_the_lattice_and_outside_furniture(
    home: dict[str, Any], shared_data: Path
) -> None:
    for room in rooms(home):
        vps = room["viewpoints"]
        assert vps == sorted(vps) and len(vps) == len({tuple(v) for v in vps})
        assert all(abs(c / 0.25 - round(c / 0.25)) < 1e-9 for v in vps for c in v)
        scene = load_scene(shared_data, room["source_scene"], "test")
        prints = obstacle_footprints(scene, RoomFrame(*room["offset"]))
        inside = [(v, f.label) for v in vps for f in prints if f.strictly_contains(*v)]
        assert not inside
        assert room["removed_viewpoints"] == (
            len(room["removed_inside_furniture"]) + room["removed_disconnected"]
        )


def test_viewpoints_come_from_the_alfred_grid(home: dict[str, Any], shared_data: Path) -> None:
    import numpy as np

    for room in rooms(home):
        raw = np.load(shared_data / f"ai2thor/alfred_layouts/{room['source_scene']}-layout.npy")
        dx, dy = room["offset"]
        grid = {(round((z + dx) / 0.25), round((-x + dy) / 0.25)) for x, z in raw.tolist()}
        kept = {(round(x / 0.25), round(y / 0.25)) for x, y in room["viewpoints"]}
        assert kept <= grid
        assert len(grid) - len(kept) == room["removed_viewpoints"]


def test_known_removals(home: dict[str, Any]) -> None:
    removed = {r["name"]: r["removed_inside_furniture"] for r in rooms(home)}
    assert {o["obstacle"].split("|")[0] for o in removed["living"]} == {"living/ArmChair"}
    assert {o["obstacle"].split("|")[0] for o in removed["bedroom"]} == {"bedroom/GarbageBag"}
    assert removed["kitchen"] == [] and removed["bathroom"] == []


def test_door_and_starts_are_viewpoints(home: dict[str, Any]) -> None:
    for room in rooms(home):
        vps = {tuple(v) for v in room["viewpoints"]}
        door = tuple(room["door"])
        assert door in vps
        neighbours = [
            (door[0] + dx, door[1] + dy)
            for dx, dy in ((0.25, 0), (-0.25, 0), (0, 0.25), (0, -0.25))
        ]
        assert sum(n in vps for n in neighbours) < 4, "door is not on the boundary"
        starts = room["starts"]
        assert [s["name"] for s in starts] == [f"{room['name']}-1", f"{room['name']}-2"]
        assert all((s["x"], s["y"]) in vps for s in starts)
        assert (starts[0]["x"], starts[0]["y"]) != (starts[1]["x"], starts[1]["y"])
        cx = sum(v[0] for v in vps) / len(vps)
        cy = sum(v[1] for v in vps) / len(vps)
        for s in starts:
            assert s["yaw"] == pytest.approx(math.atan2(cy - s["y"], cx - s["x"]), abs=1e-4)
        assert room["walkable_components"] == 1


def test_statics_container_flag_follows_openable(home: dict[str, Any], shared_data: Path) -> None:
    containers = set()
    for room in rooms(home):
        raw = json.loads(
            (shared_data / f"ai2thor/ithor_scenes/{room['source_scene']}.json").read_text()
        )
        openable = {o["objectId"]: o["openable"] for o in raw["objects"]}
        for s in room["statics"]:
            thor_id = s["id"].split("/", 1)[1]
            assert s["openable"] == openable[thor_id]
            assert s["container"] == (openable[thor_id] and s["thor_type"] != "Toilet")
            if s["container"]:
                containers.add(s["thor_type"])
    assert containers == {"Fridge", "Microwave"}


def test_one_statics_per_sink_and_bathtub(home: dict[str, Any]) -> None:
    by_room = {r["name"]: [s["thor_type"] for s in r["statics"]] for r in rooms(home)}
    assert by_room["kitchen"].count("SinkBasin") == 1 and "Sink" not in by_room["kitchen"]
    assert by_room["bathroom"].count("SinkBasin") == 1 and "Sink" not in by_room["bathroom"]
    assert by_room["bathroom"].count("BathtubBasin") == 1 and "Bathtub" not in by_room["bathroom"]
    assert by_room["bedroom"].count("Shelf") == 13


def test_objects_rest_on_their_support(home: dict[str, Any]) -> None:
    statics = {s["id"]: s for r in rooms(home) for s in r["statics"]}
    objects = {o["id"]: o for r in rooms(home) for o in r["objects"]}
    apple = objects["kitchen/Apple|-01.65|+00.81|+00.07"]
    assert apple["support"] == "kitchen/Fridge|-01.76|+00.00|00.00" and apple["inside"] is True
    # The cup sits in a wall cabinet, not a static, and more than 0.5 m above the counter.
    assert objects["kitchen/Cup|+00.90|+01.67|-01.61"]["support"] is None
    for o in objects.values():
        if o["support"] is not None:
            s = statics[o["support"]]
            assert o["inside"] == s["container"]
            assert o["id"].split("/")[0] == s["id"].split("/")[0]


def test_alfred_poses_face_their_receptacle(home: dict[str, Any]) -> None:
    # ALFRED yaws come in 90 degree steps, so a correct frame keeps every error within 45 degrees;
    # a wrong sign on yaw or a swapped axis would not.
    count = 0
    for room in rooms(home):
        for p in room["alfred_poses"]:
            x, y, yaw = p["pose"]
            heading = math.atan2(p["center"][1] - y, p["center"][0] - x)
            error = abs((heading - yaw + math.pi) % math.tau - math.pi)
            assert error <= math.radians(45.5), p["object_id"]
            assert p["on_viewpoint"]
            count += 1
    assert count == 59
