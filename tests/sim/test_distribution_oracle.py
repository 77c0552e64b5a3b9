"""The distribution oracle's reading of the generators: the stats chain and the visibility
redraws, each against a simulation of the generator's own rule."""

from __future__ import annotations

import random
from collections import Counter

import pytest

from objsearch.sim.distribution_oracle import after_redraws, chain, schedule_distribution

FRESH = {"a": 0.5, "b": 0.3, "c": 0.2}


def _draw(rng: random.Random, dist: dict[str, float], exclude: str | None = None) -> str:
    places = [p for p in sorted(dist) if p != exclude]
    return rng.choices(places, weights=[dist[p] for p in places])[0]


@pytest.mark.parametrize("steps", [1, 3])
def test_chain_is_the_stats_generators_move_rule(steps: int) -> None:
    rng, move, n = random.Random(0), 0.3, 40_000
    counts: Counter[str] = Counter()
    for _ in range(n):
        where = "a"
        for _ in range(steps):
            if rng.random() < move:
                where = _draw(rng, FRESH, exclude=where)  # a move never stays
        counts[where] += 1
    exact = chain({"a": 1.0}, FRESH, move, steps)
    assert sum(exact.values()) == pytest.approx(1.0)
    for place, p in exact.items():
        assert counts[place] / n == pytest.approx(p, abs=0.01)


def test_after_redraws_is_the_redraw_loop() -> None:
    rng, n = random.Random(1), 40_000
    dist, shares = {"a": 0.7, "b": 0.3}, {"a": 0.5, "c": 0.0}
    counts: Counter[str] = Counter()
    for _ in range(n):
        where = _draw(rng, dist)
        while rng.random() >= shares.get(where, 1.0):  # refused: drawn again, fresh
            where = _draw(rng, FRESH)
        counts[where] += 1
    exact = after_redraws(dist, FRESH, shares)
    assert "c" not in exact and sum(exact.values()) == pytest.approx(1.0)
    for place, p in exact.items():
        assert counts[place] / n == pytest.approx(p, abs=0.01)


def test_a_homes_distributions_are_probabilities() -> None:
    for schedule in ("habit-0", "stats-0"):
        for cls, dist in schedule_distribution("ithor-05", schedule).items():
            assert sum(dist.values()) == pytest.approx(1.0), (schedule, cls)
