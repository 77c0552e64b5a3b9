"""Room choice by expected cost: which room to search first, second, … (and whether the start room
comes first at all), over all orders at once.

The model (a reading beyond the paper; not yet in docs/paper-readings.md): the target is at exactly one
candidate stop, with probability ∝ its relation value, so room r holds it with P(r) = its share.
Searching room r costs its *tour* t_r — a nearest-neighbour walk from where the room is entered
(its door; the robot's position for the start room) through its stops — plus the walk to its door
from the previous room's door. Room k's walk and tour are paid only if the target was not in a
room searched before, so the expected cost of an order is

    Σ_k (d(prev_k, door_k) + t_k) · (1 − Σ_{j before k} P(j))

which has the structure of the expected-path-length objective: the same exact subset DP
(:func:`objsearch.agent.planner.epl_exact`) minimises it over all room orders, O(2^n · n²) for
n ≤ ``MAX_ROOMS`` rooms. (The tour is charged in full even if the target is in the room, so a cheap
room with the target is not favoured for being cut short: an approximation, said so.)
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from objsearch.agent.geometry import Point
from objsearch.agent.planner import epl_exact

MAX_ROOMS = 12

Distance = Callable[[Point, Point], float]


def tour_length(entry: Point, points: Sequence[Point], distance: Distance) -> float:
    """A nearest-neighbour walk from ``entry`` through ``points`` (deterministic: ties by index)."""
    rest = list(range(len(points)))
    here, total = entry, 0.0
    while rest:
        k = min(rest, key=lambda i: (distance(here, points[i]), i))
        total += distance(here, points[k])
        here = points[k]
        rest.remove(k)
    return total


def expected_cost_order(
    rooms: Sequence[str],
    start_room: str,
    here: Point,
    doors: Mapping[str, Point],
    stops: Mapping[str, Sequence[tuple[Point, float]]],
    distance: Distance,
) -> list[str]:
    """Rooms in the order of minimum expected cost (see the module doc). ``stops``: per room, each
    stop's viewpoint and relation value. Rooms without mass go last, in the given order."""
    mass = {r: sum(v for _, v in stops.get(r, ())) for r in rooms}
    live = [r for r in rooms if mass[r] > 0]
    dead = [r for r in rooms if mass[r] <= 0]
    if not live or len(live) > MAX_ROOMS:
        return [start_room, *[r for r in rooms if r != start_room]] if not live else list(rooms)
    total = sum(mass[r] for r in live)
    prob = np.array([mass[r] / total for r in live])
    entry = {r: (here if r == start_room else doors[r]) for r in live}
    tour = {r: tour_length(entry[r], [p for p, _ in stops[r]], distance) for r in live}
    start = np.array(
        [(0.0 if r == start_room else distance(here, doors[r])) + tour[r] for r in live]
    )
    n = len(live)
    dist = np.zeros((n, n))
    for i, a in enumerate(live):
        for j, b in enumerate(live):
            if i != j:
                dist[i, j] = distance(doors[a], doors[b]) + tour[b]
    ordering = epl_exact(start, dist, prob)
    return [live[k] for k in ordering.order] + dead
