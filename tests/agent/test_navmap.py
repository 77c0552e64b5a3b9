"""The navigation map of the paper home: grid edges, doors, shortest paths."""

from __future__ import annotations

import itertools
import math

import networkx as nx
import pytest

from objsearch.agent.geometry import Point
from objsearch.agent.navmap import DistanceTable, NavigationMap
from objsearch.agent.session import load_context


@pytest.fixture(scope="module")
def navmap() -> NavigationMap:
    return load_context("paper").navmap


def test_grid_edges_are_quarter_metre_steps_that_never_cut_a_corner(navmap: NavigationMap) -> None:
    g = navmap.grid
    for a, b, data in navmap.graph.edges(data=True):
        if data["teleport"]:
            continue
        assert navmap.room_of[a] == navmap.room_of[b]
        assert data["weight"] == pytest.approx(math.hypot(a.x - b.x, a.y - b.y))
        assert data["weight"] in (pytest.approx(g), pytest.approx(g * math.sqrt(2)))
        if a.x != b.x and a.y != b.y:  # a diagonal: both orthogonal neighbours are free
            assert Point(a.x, b.y) in navmap.room_of
            assert Point(b.x, a.y) in navmap.room_of


def test_rooms_meet_only_at_their_doors_at_no_cost(navmap: NavigationMap) -> None:
    teleports = [(a, b) for a, b, d in navmap.graph.edges(data=True) if d["teleport"]]
    doors = set(navmap.doors.values())
    assert len(teleports) == math.comb(len(doors), 2)
    assert all(a in doors and b in doors for a, b in teleports)
    for a, b in itertools.combinations(sorted(doors), 2):
        assert navmap.distance(a, b) == 0.0


def test_every_viewpoint_reaches_every_other(navmap: NavigationMap) -> None:
    assert nx.is_connected(navmap.graph)


def test_shortest_paths_are_symmetric_and_obey_the_triangle_inequality(
    navmap: NavigationMap,
) -> None:
    pts = sorted(navmap.room_of)[::97]
    for a, b, c in itertools.combinations(pts, 3):
        assert navmap.distance(a, b) == pytest.approx(navmap.distance(b, a))
        assert navmap.distance(a, c) <= navmap.distance(a, b) + navmap.distance(b, c) + 1e-9
        path = navmap.path(a, c)
        assert path[0] == a and path[-1] == c
        assert navmap.path_length(path) == pytest.approx(navmap.distance(a, c))


def test_within_a_room_the_path_is_at_least_the_straight_line(navmap: NavigationMap) -> None:
    for room in navmap.doors:
        pts = navmap.viewpoints(room)
        a, b = pts[0], pts[-1]
        assert navmap.distance(a, b) >= math.hypot(a.x - b.x, a.y - b.y) - 1e-9


def test_nearest_viewpoint_and_room_lookup(navmap: NavigationMap) -> None:
    for room in navmap.doors:
        for p in navmap.viewpoints(room)[::11]:
            assert navmap.room_at(p.x, p.y) == room
            assert navmap.nearest_viewpoint(p.x + 0.05, p.y - 0.05, room) == p


def test_unknown_viewpoint_is_a_clear_error(navmap: NavigationMap) -> None:
    inside = next(iter(navmap.room_of))
    with pytest.raises(ValueError, match="not reachable"):
        navmap.distance(inside, Point(-100.0, -100.0))


@pytest.mark.parametrize("home", ["paper", "ithor-02", "procthor-02"])
def test_the_maps_own_dijkstra_is_networkxs_to_the_last_tie(home: str) -> None:
    """Lengths and paths, and the order of their dicts (which ties in later min() calls
    follow), equal networkx's single_source_dijkstra over the same graph: decisions do not
    change with the implementation (a teleporting home and whole houses with links)."""
    navmap = load_context(home).navmap
    for src in sorted(navmap.room_of)[::37]:
        lengths, paths = nx.single_source_dijkstra(navmap.graph, src, weight="weight")
        ours_lengths, ours_paths = navmap.shortest_paths(src)
        assert list(ours_lengths.items()) == list(lengths.items())
        assert list(ours_paths.items()) == list(paths.items())
        # the same floats through every way of asking
        assert all(navmap.distance(src, p) == d for p, d in lengths.items())
        assert all(navmap.path(src, p) == walk for p, walk in paths.items())
    for a, b in itertools.islice(navmap.graph.edges, 0, None, 11):
        assert navmap.edge_weight(a, b) == navmap.graph.edges[a, b]["weight"]
        assert navmap.has_edge(a, b) and navmap.has_edge(b, a)


@pytest.mark.parametrize("home", ["paper", "procthor-00"])
def test_distances_and_tables_are_distance_bit_for_bit(home: str) -> None:
    """A plan's distances taken as arrays (from one point, between many, from a table built
    once) are the very floats :meth:`distance` gives, so no decision changes with the way."""
    navmap = load_context(home).navmap
    pts = sorted(navmap.room_of)[::53]
    table = navmap.table(pts)
    stored = DistanceTable(navmap, [*pts, pts[0]])  # a repeated point is held once
    assert stored.points == tuple(pts)
    picked = pts[::-2]
    for i, a in enumerate(pts):
        expected = [navmap.distance(a, b) for b in pts]
        assert navmap.distances(a, pts).tolist() == expected
        assert table[i].tolist() == expected
    assert stored.between(picked).tolist() == [
        [navmap.distance(a, b) for b in picked] for a in picked
    ]
    outside = [pts[0], next(p for p in navmap.room_of if p not in pts)]
    assert stored.between(outside).tolist() == navmap.table(outside).tolist()
    with pytest.raises(ValueError, match="not reachable"):
        navmap.distances(pts[0], [Point(-100.0, -100.0)])
    with pytest.raises(ValueError, match="not a viewpoint"):
        navmap.distances(Point(-100.0, -100.0), pts)
