"""Room order by expected cost: the DP's order is the best of all room orders under its model."""

from __future__ import annotations

import itertools
import math
import random

import pytest

from objsearch.agent.geometry import Point
from objsearch.agent.room_order import expected_cost_order, tour_length


def _euclid(a: Point, b: Point) -> float:
    return math.hypot(a.x - b.x, a.y - b.y)


def _cost(
    order: list[str],
    start_room: str,
    here: Point,
    doors: dict[str, Point],
    stops: dict[str, list[tuple[Point, float]]],
) -> float:
    total = sum(v for r in order for _, v in stops[r])
    remaining, cost, prev = 1.0, 0.0, None
    for r in order:
        entry = here if r == start_room else doors[r]
        walk = (
            0.0
            if prev is None and r == start_room
            else _euclid(here if prev is None else doors[prev], doors[r])
        )
        cost += (walk + tour_length(entry, [p for p, _ in stops[r]], _euclid)) * remaining
        remaining -= sum(v for _, v in stops[r]) / total
        prev = r
    return cost


@pytest.mark.parametrize("seed", range(6))
def test_dp_order_is_the_cheapest_of_all_orders(seed: int) -> None:
    rng = random.Random(seed)
    rooms = [f"r{i}" for i in range(5)]
    doors = {r: Point(rng.uniform(0, 10), rng.uniform(0, 10)) for r in rooms}
    stops = {
        r: [
            (
                Point(doors[r].x + rng.uniform(-2, 2), doors[r].y + rng.uniform(-2, 2)),
                rng.uniform(0.05, 1.0),
            )
            for _ in range(rng.randint(1, 3))
        ]
        for r in rooms
    }
    here = Point(doors["r0"].x + 0.5, doors["r0"].y)
    got = expected_cost_order(rooms, "r0", here, doors, stops, _euclid)
    best = min(_cost(list(p), "r0", here, doors, stops) for p in itertools.permutations(rooms))
    assert _cost(got, "r0", here, doors, stops) == pytest.approx(best)


def test_a_likely_far_room_beats_an_unlikely_start_room() -> None:
    doors = {"start": Point(0, 0), "far": Point(10, 0)}
    stops = {"start": [(Point(0, 5), 0.01)], "far": [(Point(10, 0.5), 0.99)]}
    order = expected_cost_order(["start", "far"], "start", Point(0, 0), doors, stops, _euclid)
    assert order == ["far", "start"]


def test_rooms_without_candidates_go_last() -> None:
    doors = {"a": Point(0, 0), "b": Point(3, 0), "c": Point(6, 0)}
    stops = {"a": [], "b": [(Point(3, 1), 0.5)], "c": [(Point(6, 1), 0.5)]}
    order = expected_cost_order(["a", "b", "c"], "a", Point(0, 0), doors, stops, _euclid)
    assert order[-1] == "a" and set(order) == {"a", "b", "c"}
