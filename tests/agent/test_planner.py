"""Eq. 3 and the exact planners."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from objsearch.agent.planner import (
    MAX_EXACT_STOPS,
    relation_order,
    wpl_enumerate,
    wpl_exact,
    wpl_plan,
    wpl_terms,
)


def instance(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 8, size=(n + 1, 2))
    d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    rel = rng.uniform(0, 1, size=n)
    return d[0, 1:], d[1:, 1:], rel


def test_wpl_terms_match_hand_computation() -> None:
    # Robot at 0 on a line; stops at 2 (Rel 0.5) and 5 (Rel 0.1); α = 10.
    start = np.array([2.0, 5.0])
    dist = np.array([[0.0, 3.0], [3.0, 0.0]])
    rel = np.array([0.5, 0.1])
    # Order (0, 1): 2/(1+5)/1 + 3/(1+1)/2 = 1/3 + 3/4
    assert wpl_terms((0, 1), start, dist, rel, 10.0) == pytest.approx((2 / 6, 3 / 4))
    # Order (1, 0): 5/(1+1)/1 + 3/(1+5)/2 = 5/2 + 1/4
    assert sum(wpl_terms((1, 0), start, dist, rel, 10.0)) == pytest.approx(2.75)
    best = wpl_exact(start, dist, rel, 10.0)
    assert best.order == (0, 1)
    assert best.value == pytest.approx(2 / 6 + 3 / 4)


def test_alpha_trades_distance_for_relation() -> None:
    # On a line from the robot: a stop at 2 m with Rel 0 and one at 2.5 m with Rel 1.
    start = np.array([2.0, 2.5])
    dist = np.array([[0.0, 0.5], [0.5, 0.0]])
    rel = np.array([0.0, 1.0])
    assert wpl_exact(start, dist, rel, 0.0).order == (0, 1)  # SDP: nearest first
    assert wpl_exact(start, dist, rel, 10.0).order == (1, 0)  # WPL: related first


@pytest.mark.parametrize("seed", range(150))
def test_dp_equals_enumeration(seed: int) -> None:
    n = 1 + seed % 8
    start, dist, rel = instance(n, seed)
    alpha = [0.0, 1.0, 10.0][seed % 3]
    dp = wpl_exact(start, dist, rel, alpha)
    brute = wpl_enumerate(start, dist, rel, alpha)
    assert dp.value == pytest.approx(brute.value, rel=1e-12, abs=1e-12)
    assert sorted(dp.order) == list(range(n))
    assert dp.value == pytest.approx(math.fsum(wpl_terms(dp.order, start, dist, rel, alpha)))


def test_dp_optimum_is_no_worse_than_any_order() -> None:
    start, dist, rel = instance(6, 7)
    best = wpl_exact(start, dist, rel, 10.0).value
    for perm in itertools.permutations(range(6)):
        assert best <= math.fsum(wpl_terms(perm, start, dist, rel, 10.0)) + 1e-12


def test_empty_and_single() -> None:
    empty = np.zeros(0)
    assert wpl_exact(empty, np.zeros((0, 0)), empty, 10.0).order == ()
    one = wpl_exact(np.array([3.0]), np.zeros((1, 1)), np.array([0.2]), 10.0)
    assert one.order == (0,)
    assert one.value == pytest.approx(3.0 / 3.0)


def test_bad_inputs_are_refused() -> None:
    start, dist, rel = instance(3, 1)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        wpl_exact(start, dist, rel * 5, 10.0)
    with pytest.raises(ValueError, match="shape"):
        wpl_exact(start, dist[:2], rel, 10.0)


def test_beyond_exact_limit_plan_is_complete_and_flagged() -> None:
    n = MAX_EXACT_STOPS + 2
    start, dist, rel = instance(n, 3)
    plan = wpl_plan(start, dist, rel, 10.0)
    assert not plan.exact
    assert sorted(plan.order) == list(range(n))
    exact = wpl_plan(*instance(8, 3), 10.0)
    assert exact.exact


def test_relation_order_sorts_by_rel_then_nearest() -> None:
    start = np.array([5.0, 1.0, 2.0])
    dist = np.array([[0, 4, 3], [4, 0, 1], [3, 1, 0]], dtype=float)
    rel = np.array([0.9, 0.2, 0.2])
    assert relation_order(start, dist, rel, 10.0).order == (0, 2, 1)
