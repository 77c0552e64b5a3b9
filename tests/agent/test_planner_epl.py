"""The expected-path-length planner: exact DP against brute force, and the expectation by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from objsearch.agent import planner
from objsearch.agent.planner import (
    MAX_EXACT_STOPS,
    ExpectedPathPlanner,
    PlanProblem,
    _dp_steps,
    epl_enumerate,
    epl_exact,
    epl_plan,
    epl_terms,
)


def instance(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 8, size=(n + 2, 2))
    d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    p = rng.dirichlet(np.ones(n + 1))[:n]  # some mass left for later rooms
    return d[0, 2:], d[2:, 2:], p, d[1, 2:]


def test_epl_terms_by_hand() -> None:
    # Robot at 0 on a line; stops at 2 (p = 0.5) and 5 (p = 0.3); the next room's entry at 9.
    start = np.array([2.0, 5.0])
    dist = np.array([[0.0, 3.0], [3.0, 0.0]])
    prob = np.array([0.5, 0.3])
    to_exit = np.array([7.0, 4.0])
    assert epl_terms((0, 1), start, dist, prob, to_exit) == pytest.approx((2.0, 1.5, 0.8))
    assert epl_terms((1, 0), start, dist, prob, to_exit) == pytest.approx((5.0, 2.1, 1.4))


@pytest.mark.parametrize("n", range(1, 8))
@pytest.mark.parametrize("seed", range(4))
def test_dp_equals_brute_force(n: int, seed: int) -> None:
    start, dist, prob, to_exit = instance(n, seed)
    for exit_ in (None, to_exit):
        dp = epl_exact(start, dist, prob, exit_)
        bf = epl_enumerate(start, dist, prob, exit_)
        assert dp.value == pytest.approx(bf.value, rel=1e-12, abs=1e-12)
        assert sorted(dp.order) == list(range(n))


def test_probable_far_stop_can_go_first() -> None:
    # A stop 4 m away holding the target with p = 0.9 beats one 1 m away with p = 0.05 (a
    # nearest-first order would walk 1 + 5 · 0.95 = 5.75 m expected; far-first 4 + 5 · 0.1 = 4.5).
    start = np.array([1.0, 4.0])
    dist = np.array([[0.0, 5.0], [5.0, 0.0]])
    plan = ExpectedPathPlanner().plan(PlanProblem(start, dist, np.array([0.05, 0.9])))
    assert plan.order == (1, 0)
    assert plan.value == pytest.approx(4.0 + 5.0 * (1 - 0.9 / 0.95))


def test_planner_normalises_rel_with_the_mass_of_later_rooms() -> None:
    start = np.array([1.0, 4.0])
    dist = np.array([[0.0, 5.0], [5.0, 0.0]])
    rel = np.array([0.2, 0.4])
    plan = ExpectedPathPlanner().plan(PlanProblem(start, dist, rel, None, rest_mass=0.4))
    prob = rel / 1.0
    assert plan.value == pytest.approx(epl_enumerate(start, dist, prob).value)


def test_zero_mass_falls_back_to_uniform_and_large_rooms_truncate() -> None:
    start, dist, _, _ = instance(3, 1)
    plan = ExpectedPathPlanner().plan(PlanProblem(start, dist, np.zeros(3)))
    assert math.isclose(plan.value, epl_enumerate(start, dist, np.full(3, 1 / 3)).value)
    n = MAX_EXACT_STOPS + 2
    start, dist, prob, _ = instance(n, 2)
    big = ExpectedPathPlanner().plan(PlanProblem(start, dist, prob))
    assert not big.exact and sorted(big.order) == list(range(n))


@pytest.mark.parametrize("seed", range(3))
def test_epl_plan_is_exact_up_to_its_size_and_says_when_it_is_not(seed: int) -> None:
    start, dist, prob, _ = instance(9, seed)
    exact = epl_plan(start, dist, prob, max_exact=9)
    assert exact.exact and exact.value == pytest.approx(epl_exact(start, dist, prob).value)
    bounded = epl_plan(start, dist, prob, max_exact=6)
    assert not bounded.exact and sorted(bounded.order) == list(range(9))
    # An approximation, never better than the optimum.
    assert bounded.value >= exact.value - 1e-9


def _grid_instance(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Stops on a small integer grid with probabilities in tenths: many equal legs and sums, so
    the DP meets ties at every layer."""
    rng = np.random.default_rng(seed)
    pts = rng.integers(0, 4, size=(n + 2, 2)).astype(float)
    d = np.abs(pts[:, None] - pts[None]).sum(axis=2)
    p = np.round(rng.dirichlet(np.ones(n + 1))[:n], 1)
    return d[0, 2:], d[2:, 2:], p, d[1, 2:]


@pytest.mark.parametrize("n", [1, 2, 5, 9, 12])
def test_the_dp_plans_the_same_with_its_index_arrays_kept_or_made_anew(
    n: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The DP keeps the index arrays that depend on the number of stops alone between calls (a
    decision's first plan then does not make them); the plan, ties and terms included, is the
    same as when each call makes its own (beyond CACHED_DP_STOPS)."""
    problems = [f(n, seed) for seed in range(3) for f in (instance, _grid_instance)]
    kept = [epl_exact(s, d, p, e) for s, d, p, e in problems]
    assert _dp_steps(n) is _dp_steps(n)
    assert not _dp_steps(n)[0][0].flags.writeable
    monkeypatch.setattr(planner, "CACHED_DP_STOPS", 0)
    made = [epl_exact(s, d, p, e) for s, d, p, e in problems]
    assert [(o.order, o.terms) for o in kept] == [(o.order, o.terms) for o in made]
