"""The navigation map: viewpoints on a 0.25 m grid, joined into one metric graph.

Homes built from whole houses (ProcTHOR) have no teleport: their rooms share one floor plan and are
joined by ``links``, the walkable steps through doors and open walls.

Within a room, neighbouring viewpoints are joined 8-connected (a diagonal step only where both
orthogonal neighbours exist, so paths never cut a furniture corner). Rooms are joined the paper's way:
a robot standing at a room's entry viewpoint can be teleported to any other room's entry viewpoint
at no cost (paper §6.1), modelled as zero-length edges between doors.
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import numpy.typing as npt

from objsearch.agent.geometry import Point
from objsearch.agent.home import Home

if TYPE_CHECKING:
    import networkx as nx

#: An edge's attributes, shared by both directions: ``weight`` (metres) and ``teleport``.
Edge = dict[str, Any]
FloatArray = npt.NDArray[np.float64]


@dataclass
class NavigationMap:
    """The graph as adjacency dicts, in the order its nodes and edges were added, and Dijkstra
    over them as networkx's ``single_source_dijkstra`` does it (same order, same ties, same
    sums): a search needs no networkx import (a third of its start-up). :attr:`graph` is the
    same graph as a networkx ``Graph``, built on first use."""

    room_of: dict[Point, str]
    doors: dict[str, Point]
    grid: float
    _by_room: dict[str, tuple[Point, ...]] = field(default_factory=dict)
    _adj: dict[Point, dict[Point, Edge]] = field(default_factory=dict, repr=False)
    #: every add_edge, in order (a networkx graph built from them has the same adjacency order)
    _added: list[tuple[Point, Point]] = field(default_factory=list, repr=False)
    _graph: nx.Graph | None = field(default=None, repr=False, compare=False)
    #: the viewpoints by index, and each one's neighbours as (index, metres) in adjacency order:
    #: Dijkstra over ints runs several times faster than over Points (a tuple hash per visit)
    _nodes: list[Point] = field(default_factory=list, repr=False, compare=False)
    _index: dict[Point, int] = field(default_factory=dict, repr=False, compare=False)
    _nbrs: list[tuple[tuple[int, float], ...]] = field(
        default_factory=list, repr=False, compare=False
    )
    #: each source's shortest-path tree, built on first use and kept: it depends on the map alone
    _trees: dict[Point, _Tree] = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def from_home(cls, home: Home) -> NavigationMap:
        adj: dict[Point, dict[Point, Edge]] = {}
        added: list[tuple[Point, Point]] = []

        def add_edge(p: Point, q: Point, weight: float, teleport: bool) -> None:
            # As networkx.Graph.add_edge: a new edge is appended to both ends' neighbours; an
            # edge added again keeps its place and takes the new attributes.
            edge = adj[p].get(q)
            if edge is None:
                adj[p][q] = adj[q][p] = {"weight": weight, "teleport": teleport}
            else:
                edge.update(weight=weight, teleport=teleport)
            added.append((p, q))

        room_of: dict[Point, str] = {}
        g = home.grid
        for room in home.rooms:
            pts = set(room.viewpoints)
            for p in room.viewpoints:
                room_of[p] = room.name
                adj.setdefault(p, {})
            for p in room.viewpoints:
                for dx, dy in ((1, 0), (0, 1), (1, 1), (1, -1)):
                    q = _snap(p.x + dx * g, p.y + dy * g)
                    if q not in pts:
                        continue
                    if (
                        dx
                        and dy
                        and (
                            _snap(p.x + dx * g, p.y) not in pts
                            or _snap(p.x, p.y + dy * g) not in pts
                        )
                    ):
                        continue
                    add_edge(p, q, g * math.hypot(dx, dy), False)
        for p, q in home.links:
            if p not in room_of or q not in room_of:
                raise ValueError(
                    f"home {home.name!r}: link {p}–{q} joins points that are no viewpoints"
                )
            add_edge(p, q, math.hypot(p.x - q.x, p.y - q.y), False)
        doors = {room.name: room.door for room in home.rooms}
        names = list(doors)
        if home.teleport:
            for i, a in enumerate(names):
                for b in names[i + 1 :]:
                    add_edge(doors[a], doors[b], 0.0, True)
        by_room = {room.name: room.viewpoints for room in home.rooms}
        return cls(room_of=room_of, doors=doors, grid=g, _by_room=by_room, _adj=adj, _added=added)

    @property
    def graph(self) -> nx.Graph:
        """The map as a networkx graph (nodes and edges in the same order, ``weight`` and
        ``teleport`` on each edge), built on first use."""
        if self._graph is None:
            import networkx as nx

            graph = nx.Graph()
            graph.add_nodes_from(self._adj)
            for p, q in self._added:
                graph.add_edge(p, q, **self._adj[p][q])
            self._graph = graph
        return self._graph

    def viewpoints(self, room: str) -> tuple[Point, ...]:
        return self._by_room[room]

    def nearest_viewpoint(self, x: float, y: float, room: str) -> Point:
        """The room's viewpoint closest (Euclidean) to (x, y); ties go to the smaller (x, y)."""
        return min(self._by_room[room], key=lambda p: (math.hypot(p.x - x, p.y - y), p))

    def room_at(self, x: float, y: float) -> str:
        """The room of the viewpoint at (x, y), or of the nearest viewpoint off the grid."""
        room = self.room_of.get(_snap(x, y))
        if room is None:
            nearest = min(self.room_of, key=lambda p: (math.hypot(p.x - x, p.y - y), p))
            room = self.room_of[nearest]
        return room

    def _tree(self, src: Point) -> _Tree:
        tree = self._trees.get(src)
        if tree is not None:
            return tree
        if not self._nodes:
            self._nodes = list(self._adj)
            self._index = {p: i for i, p in enumerate(self._nodes)}
            index = self._index
            self._nbrs = [
                tuple((index[q], edge["weight"]) for q, edge in self._adj[p].items())
                for p in self._nodes
            ]
        s = self._index.get(src)
        if s is None:
            raise ValueError(f"{src} is not a viewpoint of this map")
        # networkx's _dijkstra_multisource for one source, spelled out over indices: the heap
        # breaks ties by push order, neighbours are visited in insertion order, a node's
        # predecessor is the first that reached it by the shortest length. The same lengths (the
        # source's an int 0, as networkx has it) and paths; ``order`` is networkx's dict order.
        nbrs = self._nbrs
        n = len(nbrs)
        done = bytearray(n)
        seen: list[float] = [math.inf] * n
        seen[s] = 0
        pred = [-1] * n
        order: list[int] = []
        pushed = 0
        fringe: list[tuple[float, int, int]] = [(0, 0, s)]
        pop, push = heapq.heappop, heapq.heappush
        while fringe:
            dist_v, _, v = pop(fringe)
            if done[v]:
                continue
            done[v] = 1
            order.append(v)
            for u, weight in nbrs[v]:
                if done[u]:
                    continue  # weights are >= 0: never shorter (networkx raises if it were)
                vu_dist = dist_v + weight
                if vu_dist < seen[u]:
                    seen[u] = vu_dist
                    pushed += 1
                    push(fringe, (vu_dist, pushed, u))
                    pred[u] = v
        tree = self._trees[src] = _Tree(seen, np.array(seen, dtype=float), pred, order)
        return tree

    def distance(self, a: Point, b: Point) -> float:
        lengths = self._tree(a).lengths
        i = self._index.get(b)
        if i is None or lengths[i] == math.inf:
            raise ValueError(f"viewpoint {b} is not reachable from {a}")
        return lengths[i]

    def path(self, a: Point, b: Point) -> list[Point]:
        self.distance(a, b)
        pred, nodes = self._trees[a].pred, self._nodes
        i = self._index[b]
        walk = [nodes[i]]
        while (i := pred[i]) >= 0:
            walk.append(nodes[i])
        walk.reverse()
        return walk

    def shortest_paths(self, src: Point) -> tuple[dict[Point, float], dict[Point, list[Point]]]:
        """Every reachable viewpoint's length and path from ``src``, in the order Dijkstra
        settled them (as networkx's ``single_source_dijkstra`` returns them)."""
        tree = self._tree(src)
        settled = [self._nodes[i] for i in tree.order]
        return (
            {p: tree.lengths[i] for p, i in zip(settled, tree.order, strict=True)},
            {p: self.path(src, p) for p in settled},
        )

    def distances(self, src: Point, targets: Sequence[Point]) -> FloatArray:
        """Metres from ``src`` to each of ``targets`` (:meth:`distance`'s values, as an array)."""
        tree = self._tree(src)
        try:
            picked = tree.array[[self._index[b] for b in targets]]
        except KeyError as exc:
            raise ValueError(f"viewpoint {exc.args[0]} is not reachable from {src}") from None
        if not np.isfinite(picked).all():
            raise ValueError(f"a viewpoint of {list(targets)} is not reachable from {src}")
        return picked

    def table(self, points: Sequence[Point]) -> FloatArray:
        """Metres between each pair of ``points``: row i holds :meth:`distances` from point i
        (so ``table(ps)[i, j] == distance(ps[i], ps[j])``, bit for bit)."""
        if not points:
            return np.zeros((0, 0))
        return np.stack([self.distances(p, points) for p in points])

    def path_length(self, path: Sequence[Point]) -> float:
        return math.fsum(self._adj[u][v]["weight"] for u, v in itertools.pairwise(path))

    def edge_weight(self, a: Point, b: Point) -> float:
        """The length of the edge a–b (``KeyError`` if there is none)."""
        weight: float = self._adj[a][b]["weight"]
        return weight

    def has_edge(self, a: Point, b: Point) -> bool:
        return b in self._adj.get(a, {})

    def is_teleport(self, a: Point, b: Point) -> bool:
        return bool(self._adj[a][b]["teleport"])


class DistanceTable:
    """Metres between each pair of a fixed set of viewpoints (a home's stops), computed once:
    a decision then takes its stops' distances by indexing instead of one :meth:`~NavigationMap.
    distance` call per pair."""

    def __init__(self, navmap: NavigationMap, points: Sequence[Point]) -> None:
        self.navmap = navmap
        self.points = tuple(dict.fromkeys(points))
        self._index = {p: i for i, p in enumerate(self.points)}
        self.matrix = navmap.table(self.points)

    def between(self, points: Sequence[Point]) -> FloatArray:
        """``navmap.table(points)``, taken from the table (asked directly of the map for
        points the table does not hold)."""
        try:
            rows = [self._index[p] for p in points]
        except KeyError:
            return self.navmap.table(points)
        return self.matrix[np.ix_(rows, rows)]


class _Tree(NamedTuple):
    """One source's shortest-path tree, by viewpoint index (:attr:`NavigationMap._nodes`)."""

    #: metres (the source's an int 0, unreached ones inf), as a list and as an array
    lengths: list[float]
    array: FloatArray
    #: each viewpoint's predecessor on its path (-1: the source, or unreached)
    pred: list[int]
    #: the viewpoints in the order they were settled
    order: list[int]


def _snap(x: float, y: float) -> Point:
    return Point(round(x, 4), round(y, 4))
