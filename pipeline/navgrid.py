"""Navigation-grid geometry on integer cells of a 0.25 m lattice.

Cells are ``(i, j)`` with ``x = i * grid``, ``y = j * grid`` in the ROS floor plane, so equality and
neighbourhood are exact; floats only appear when a result is written out.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

Cell = tuple[int, int]

GRID_M = 0.25
# A lattice point may be off by float noise in the source; anything larger is a different grid.
_LATTICE_TOL = 1e-6
# Path lengths are sums of 0.25 and 0.25*sqrt(2); values closer than this are the same length.
_LENGTH_TOL = 1e-9

NEIGHBOURS_4: tuple[Cell, ...] = ((1, 0), (-1, 0), (0, 1), (0, -1))
DIAGONALS: tuple[Cell, ...] = ((1, 1), (1, -1), (-1, 1), (-1, -1))
NEIGHBOURS_8: tuple[Cell, ...] = NEIGHBOURS_4 + DIAGONALS


@dataclass(frozen=True)
class Footprint:
    """An axis-aligned floor rectangle (ROS x, y) of something the robot cannot stand in."""

    label: str
    x_min: float
    x_max: float
    y_min: float
    y_max: float

    def strictly_contains(self, x: float, y: float) -> bool:
        return self.x_min < x < self.x_max and self.y_min < y < self.y_max


def to_cell(x: float, y: float, grid: float = GRID_M) -> Cell | None:
    """The lattice cell of (x, y), or None if the point is not on the lattice."""
    i, j = round(x / grid), round(y / grid)
    if abs(i * grid - x) > _LATTICE_TOL or abs(j * grid - y) > _LATTICE_TOL:
        return None
    return (i, j)


def cell_xy(cell: Cell, grid: float = GRID_M) -> tuple[float, float]:
    return (cell[0] * grid, cell[1] * grid)


def split_by_footprints(
    cells: Iterable[Cell], footprints: Iterable[Footprint], grid: float = GRID_M
) -> tuple[set[Cell], dict[Cell, str]]:
    """Cells outside every footprint, and the removed cells with the footprint that removed them."""
    prints = tuple(footprints)
    kept: set[Cell] = set()
    removed: dict[Cell, str] = {}
    for cell in cells:
        x, y = cell_xy(cell, grid)
        hit = next((f.label for f in prints if f.strictly_contains(x, y)), None)
        if hit is None:
            kept.add(cell)
        else:
            removed[cell] = hit
    return kept, removed


def components_8(cells: Iterable[Cell]) -> list[frozenset[Cell]]:
    """8-connected components, largest first; equal sizes ordered by their smallest cell."""
    todo = set(cells)
    found: list[frozenset[Cell]] = []
    while todo:
        seed = min(todo)
        todo.discard(seed)
        stack, part = [seed], {seed}
        while stack:
            ci, cj = stack.pop()
            for di, dj in NEIGHBOURS_8:
                nb = (ci + di, cj + dj)
                if nb in todo:
                    todo.discard(nb)
                    part.add(nb)
                    stack.append(nb)
        found.append(frozenset(part))
    return sorted(found, key=lambda c: (-len(c), min(c)))


def boundary(cells: frozenset[Cell] | set[Cell]) -> list[Cell]:
    """Cells missing at least one of their four orthogonal neighbours, sorted."""
    return sorted(
        c for c in cells if any((c[0] + di, c[1] + dj) not in cells for di, dj in NEIGHBOURS_4)
    )


def door(cells: frozenset[Cell] | set[Cell]) -> Cell:
    """The paper's sampling point: the boundary cell nearest the boundary's median coordinate.

    The median is taken per axis; ties in distance go to the smallest (x, y).
    """
    edge = boundary(cells)
    if not edge:
        raise ValueError("a grid without boundary cells has no door")
    mi = statistics.median(c[0] for c in edge)
    mj = statistics.median(c[1] for c in edge)
    # Medians are integers or halves, so these squared distances are exact in floating point.
    return min(edge, key=lambda c: ((c[0] - mi) ** 2 + (c[1] - mj) ** 2, c))


def _step_allowed(cells: frozenset[Cell] | set[Cell], cell: Cell, step: Cell) -> bool:
    """Orthogonal steps need the target; diagonal steps also need both cells they cut past."""
    ci, cj = cell
    di, dj = step
    if (ci + di, cj + dj) not in cells:
        return False
    if di and dj:
        return (ci + di, cj) in cells and (ci, cj + dj) in cells
    return True


def shortest_path_lengths(
    cells: frozenset[Cell] | set[Cell], grid: float = GRID_M
) -> tuple[list[Cell], np.ndarray]:
    """All-pairs walking distances (metres) over the grid graph; ``inf`` where unreachable.

    Floyd-Warshall on a dense matrix: rooms hold at most a few hundred cells, where this is
    faster in numpy than repeated Dijkstra in Python.
    """
    nodes = sorted(cells)
    index = {c: k for k, c in enumerate(nodes)}
    n = len(nodes)
    dist = np.full((n, n), np.inf)
    np.fill_diagonal(dist, 0.0)
    diagonal = grid * math.sqrt(2.0)
    for c, k in index.items():
        for step in NEIGHBOURS_8:
            if _step_allowed(cells, c, step):
                other = index[(c[0] + step[0], c[1] + step[1])]
                dist[k, other] = diagonal if step[0] and step[1] else grid
    for k in range(n):
        np.minimum(dist, dist[:, k, None] + dist[None, k, :], out=dist)
    return nodes, dist


def farthest_pair(
    cells: frozenset[Cell] | set[Cell], grid: float = GRID_M
) -> tuple[Cell, Cell, float]:
    """The two cells farthest apart by walking distance; ties go to the smallest sorted pair.

    Unreachable pairs are ignored (a diagonal-only link joins cells 8-connected but not walkable).
    """
    nodes, dist = shortest_path_lengths(cells, grid)
    if len(nodes) < 2:
        raise ValueError("a grid needs at least two cells for two start points")
    finite = np.where(np.isfinite(dist), dist, -1.0)
    best = float(finite.max())
    rows, cols = np.nonzero(np.triu(finite >= best - _LENGTH_TOL, k=1))
    # nonzero() scans row-major, and nodes are sorted, so the first hit is the smallest pair.
    a, b = int(rows[0]), int(cols[0])
    return nodes[a], nodes[b], best


def walkable_pieces(cells: frozenset[Cell] | set[Cell]) -> list[frozenset[Cell]]:
    """The pieces of the walking graph (corner-cutting diagonals excluded), largest first; equal
    sizes ordered by their smallest cell."""
    todo = set(cells)
    found: list[frozenset[Cell]] = []
    while todo:
        seed = min(todo)
        todo.discard(seed)
        stack, part = [seed], {seed}
        while stack:
            c = stack.pop()
            for step in NEIGHBOURS_8:
                nb = (c[0] + step[0], c[1] + step[1])
                if nb in todo and _step_allowed(cells, c, step):
                    todo.discard(nb)
                    part.add(nb)
                    stack.append(nb)
        found.append(frozenset(part))
    return sorted(found, key=lambda c: (-len(c), min(c)))


def walkable_components(cells: frozenset[Cell] | set[Cell]) -> int:
    """How many pieces the walking graph (corner-cutting diagonals excluded) has."""
    return len(walkable_pieces(cells))
