"""Grid rules on small hand-made grids, where the right answer is obvious."""

from __future__ import annotations

import math

import pytest

from objsearch.pipeline import navgrid
from objsearch.pipeline.navgrid import Footprint


def rect(w: int, h: int) -> set[tuple[int, int]]:
    return {(i, j) for i in range(w) for j in range(h)}


def test_components_keep_diagonal_links_and_order_by_size() -> None:
    cells = {(0, 0), (1, 1), (2, 2), (10, 10), (10, 11)}
    parts = navgrid.components_8(cells)
    assert parts[0] == frozenset({(0, 0), (1, 1), (2, 2)})
    assert parts[1] == frozenset({(10, 10), (10, 11)})


def test_diagonal_steps_do_not_cut_corners() -> None:
    assert navgrid.walkable_components({(0, 0), (1, 1)}) == 2
    assert navgrid.walkable_components({(0, 0), (1, 1), (0, 1)}) == 1
    _, dist = navgrid.shortest_path_lengths({(0, 0), (1, 0), (0, 1), (1, 1)})
    assert dist[0, 3] == pytest.approx(0.25 * math.sqrt(2))


def test_boundary_and_door_of_a_rectangle() -> None:
    cells = rect(5, 3)
    edge = navgrid.boundary(cells)
    assert (2, 1) not in edge and len(edge) == 15 - 3
    # Boundary medians are (2, 1), the interior centre: the nearest boundary cells are (2, 0) and
    # (2, 2) at distance 1, and (1, 1)/(3, 1) are interior; ties go to the smaller cell.
    assert navgrid.door(cells) == (2, 0)
    assert navgrid.door(cells) in edge


def test_farthest_pair_on_an_l_shape_walks_around_the_corner() -> None:
    cells = {(i, 0) for i in range(6)} | {(0, j) for j in range(6)}
    a, b, length = navgrid.farthest_pair(cells)
    assert (a, b) == ((0, 5), (5, 0))
    assert length == pytest.approx(10 * 0.25)


def test_farthest_pair_ties_go_to_the_smallest_pair() -> None:
    # Both diagonals of a 3x3 square are 2 diagonal steps long.
    a, b, length = navgrid.farthest_pair(rect(3, 3))
    assert (a, b) == ((0, 0), (2, 2))
    assert length == pytest.approx(2 * 0.25 * math.sqrt(2))


def test_footprints_drop_only_strictly_inside_points() -> None:
    sofa = Footprint("sofa", 0.1, 0.6, -0.1, 0.3)
    kept, removed = navgrid.split_by_footprints({(0, 0), (1, 0), (2, 0), (3, 0)}, [sofa])
    assert removed == {(1, 0): "sofa", (2, 0): "sofa"}
    edge = Footprint("edge", 0.25, 0.5, -0.1, 0.1)  # (0.25, 0) and (0.5, 0) lie on its border
    assert navgrid.split_by_footprints({(1, 0), (2, 0)}, [edge])[1] == {}
    assert kept == {(0, 0), (3, 0)}


def test_off_lattice_points_are_refused() -> None:
    assert navgrid.to_cell(0.5, -1.25) == (2, -5)
    assert navgrid.to_cell(0.5, 0.1) is None
