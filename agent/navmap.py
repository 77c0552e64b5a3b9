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
from typing import TYPE_CHECKING, Any

from objsearch.agent.geometry import Point
from objsearch.agent.home import Home

if TYPE_CHECKING:
    import networkx as nx

#: An edge's attributes, shared by both directions: ``weight`` (metres) and ``teleport``.
Edge = dict[str, Any]


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
    _lengths: dict[Point, dict[Point, float]] = field(default_factory=dict)
    _paths: dict[Point, dict[Point, list[Point]]] = field(default_factory=dict)

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

    def _single_source(self, src: Point) -> None:
        if src in self._lengths:
            return
        # networkx's _dijkstra_multisource for one source, spelled out: the heap breaks ties by
        # push order, neighbours are visited in insertion order, a path is its first
        # predecessor's plus the node. The same lengths and paths, in the same dict order.
        adj = self._adj
        if src not in adj:
            raise ValueError(f"{src} is not a viewpoint of this map")
        dist: dict[Point, float] = {}
        seen: dict[Point, float] = {src: 0}
        pred: dict[Point, Point] = {}
        counter = itertools.count()
        fringe: list[tuple[float, int, Point]] = [(0, next(counter), src)]
        while fringe:
            dist_v, _, v = heapq.heappop(fringe)
            if v in dist:
                continue
            dist[v] = dist_v
            for u, edge in adj[v].items():
                vu_dist = dist_v + edge["weight"]
                if u in dist:
                    continue  # weights are >= 0: never shorter (networkx raises if it were)
                if u not in seen or vu_dist < seen[u]:
                    seen[u] = vu_dist
                    heapq.heappush(fringe, (vu_dist, next(counter), u))
                    pred[u] = v
        paths: dict[Point, list[Point]] = {src: [src]}
        for v in itertools.islice(dist, 1, None):
            paths[v] = paths[pred[v]] + [v]
        self._lengths[src] = dist
        self._paths[src] = paths

    def distance(self, a: Point, b: Point) -> float:
        self._single_source(a)
        try:
            return self._lengths[a][b]
        except KeyError:
            raise ValueError(f"viewpoint {b} is not reachable from {a}") from None

    def path(self, a: Point, b: Point) -> list[Point]:
        self.distance(a, b)
        return self._paths[a][b]

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


def _snap(x: float, y: float) -> Point:
    return Point(round(x, 4), round(y, 4))
