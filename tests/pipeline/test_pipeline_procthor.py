"""ProcTHOR import: a connected walking graph whose rooms are joined through doorways."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import networkx as nx
import pytest

from objsearch.agent.home import load_home
from objsearch.agent.navmap import NavigationMap
from objsearch.pipeline.procthor import MAX_LINK_M, build_procthor_home

HOUSE = Path("procthor_houses/houses_20/house_0.json")


@pytest.fixture(scope="module")
def home_file(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    doc = build_procthor_home(shared_data, "house0", HOUSE).doc
    path = tmp_path_factory.mktemp("procthor") / "house0.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


def test_walking_graph_is_connected_without_teleports(home_file: Path) -> None:
    home = load_home(home_file)
    assert not home.teleport and home.links
    navmap = NavigationMap.from_home(home)
    assert nx.is_connected(navmap.graph)
    assert not any(d["teleport"] for _, _, d in navmap.graph.edges(data=True))
    assert {r.room_type for r in home.rooms} == {"Bedroom", "Bathroom", "Kitchen", "LivingRoom"}


def test_rooms_are_joined_only_by_short_door_steps(home_file: Path, shared_data: Path) -> None:
    home = load_home(home_file)
    navmap = NavigationMap.from_home(home)
    crossings = [(a, b) for a, b in navmap.graph.edges if navmap.room_of[a] != navmap.room_of[b]]
    assert crossings and all(
        0 < navmap.graph.edges[a, b]["weight"] <= MAX_LINK_M for a, b in crossings
    )
    # Every pair of rooms the house joins by a door has at least one step between them.
    house = json.loads((shared_data / HOUSE).read_text())
    names = {r.source_scene.split("#")[1]: r.name for r in home.rooms}
    doors = {
        frozenset((names[d["room0"]], names[d["room1"]]))
        for d in house["doors"]
        if d["room0"] != d["room1"]
    }
    joined = {frozenset((navmap.room_of[a], navmap.room_of[b])) for a, b in crossings}
    assert doors <= joined


def test_walking_between_rooms_passes_through_a_door_and_costs_metres(home_file: Path) -> None:
    home = load_home(home_file)
    navmap = NavigationMap.from_home(home)
    for a, b in itertools.combinations(home.rooms, 2):
        path = navmap.path(a.starts[0][1].point, b.starts[0][1].point)
        rooms = [navmap.room_of[p] for p in path]
        assert rooms[0] == a.name and rooms[-1] == b.name
        changes = [
            (p, q) for p, q in itertools.pairwise(path) if navmap.room_of[p] != navmap.room_of[q]
        ]
        link_set = {frozenset(link) for link in home.links}
        assert changes and all(frozenset(c) in link_set for c in changes)
        assert navmap.path_length(path) > 0.5


def test_statics_and_viewpoints_avoid_furniture(home_file: Path) -> None:
    home = load_home(home_file)
    statics = [s for r in home.rooms for s in r.statics]
    assert {"Bed", "Toilet", "Fridge"} <= {s.cls for s in statics}
    for room in home.rooms:
        for s in room.statics:
            if s.box.center[2] - s.box.size[2] / 2 < 0.3:  # floor-standing
                assert not any(s.box.contains_xy(p) for p in room.viewpoints)
