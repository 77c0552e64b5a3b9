"""The navigation map: viewpoints on a 0.25 m grid, joined into one metric graph.

Homes built from whole houses (ProcTHOR) have no teleport: their rooms share one floor plan and are
joined by ``links``, the walkable steps through doors and open walls.

Within a room, neighbouring viewpoints are joined 8-connected (a diagonal step only where both
orthogonal neighbours exist, so paths never cut a furniture corner). Rooms are joined the paper's way:
a robot standing at a room's entry viewpoint can be teleported to any other room's entry viewpoint
at no cost (paper §6.1), modelled as zero-length edges between doors.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import networkx as nx

from objsearch.agent.geometry import Point
from objsearch.agent.home import Home


@dataclass
class NavigationMap:
    graph: nx.Graph
    room_of: dict[Point, str]
    doors: dict[str, Point]
    grid: float
    _by_room: dict[str, tuple[Point, ...]] = field(default_factory=dict)
    _lengths: dict[Point, dict[Point, float]] = field(default_factory=dict)
    _paths: dict[Point, dict[Point, list[Point]]] = field(default_factory=dict)

    @classmethod
    def from_home(cls, home: Home) -> NavigationMap:
        graph = nx.Graph()
        room_of: dict[Point, str] = {}
        g = home.grid
        for room in home.rooms:
            pts = set(room.viewpoints)
            for p in room.viewpoints:
                room_of[p] = room.name
                graph.add_node(p)
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
                    graph.add_edge(p, q, weight=g * math.hypot(dx, dy), teleport=False)
        for p, q in home.links:
            if p not in room_of or q not in room_of:
                raise ValueError(
                    f"home {home.name!r}: link {p}–{q} joins points that are no viewpoints"
                )
            graph.add_edge(p, q, weight=math.hypot(p.x - q.x, p.y - q.y), teleport=False)
        doors = {room.name: room.door for room in home.rooms}
        names = list(doors)
        if home.teleport:
            for i, a in enumerate(names):
                for b in names[i + 1 :]:
                    graph.add_edge(doors[a], doors[b], weight=0.0, teleport=True)
        by_room = {room.name: room.viewpoints for room in home.rooms}
        return cls(graph=graph, room_of=room_of, doors=doors, grid=g, _by_room=by_room)

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
        if src not in self._lengths:
            lengths, paths = nx.single_source_dijkstra(self.graph, src, weight="weight")
            self._lengths[src] = lengths
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
        return math.fsum(self.graph.edges[u, v]["weight"] for u, v in itertools.pairwise(path))

    def is_teleport(self, a: Point, b: Point) -> bool:
        return bool(self.graph.edges[a, b]["teleport"])


def _snap(x: float, y: float) -> Point:
    return Point(round(x, 4), round(y, 4))
