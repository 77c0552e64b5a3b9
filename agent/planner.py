"""Visiting orders: the paper's WPL (Eq. 3) found exactly, and its baselines.

WPL of an order (s_0, …, s_{n-1}) from the robot's position p is

    WPL = Σ_i  L_i / ((1 + α·Rel(target, s_i)) · 2^i),   L_0 = d(p, s_0),  L_i = d(s_{i-1}, s_i)

The index starts at 0 (the first leg is not halved) and the sum ends at the last stop: the end point of
the search is unknown when planning, so it cannot be a term (docs/paper-readings.md).

Because the discount 2^i depends only on how many stops came before, the minimum over all n! orders
is a shortest path over (visited set, last stop) states: an exact subset dynamic program in
O(2^n · n²) time, vectorised with numpy per popcount layer.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

#: Largest number of stops planned exactly; the DP table holds 2^n · n floats (n = 18: 38 MB).
MAX_EXACT_STOPS = 18


@dataclass(frozen=True, slots=True)
class Ordering:
    """A visiting order (indices into the candidate list) and its objective terms."""

    order: tuple[int, ...]
    terms: tuple[float, ...]
    exact: bool = True

    @property
    def value(self) -> float:
        return math.fsum(self.terms)


def _check(start: FloatArray, dist: FloatArray, rel: FloatArray) -> int:
    n = len(start)
    if dist.shape != (n, n) or rel.shape != (n,):
        raise ValueError(f"shape mismatch: start {start.shape}, dist {dist.shape}, rel {rel.shape}")
    if np.any(rel < 0) or np.any(rel > 1):
        raise ValueError("relation values must lie in [0, 1]")
    return n


def wpl_terms(
    order: Sequence[int], start: FloatArray, dist: FloatArray, rel: FloatArray, alpha: float
) -> tuple[float, ...]:
    """The terms of Eq. 3 for one order."""
    terms: list[float] = []
    prev: int | None = None
    for i, k in enumerate(order):
        leg = start[k] if prev is None else dist[prev, k]
        terms.append(float(leg) / ((1.0 + alpha * float(rel[k])) * 2.0**i))
        prev = k
    return tuple(terms)


def wpl_enumerate(start: FloatArray, dist: FloatArray, rel: FloatArray, alpha: float) -> Ordering:
    """Minimum-WPL order by trying all n! orders (the reference the DP is tested against)."""
    n = _check(start, dist, rel)
    best: tuple[float, tuple[int, ...]] | None = None
    for perm in itertools.permutations(range(n)):
        value = math.fsum(wpl_terms(perm, start, dist, rel, alpha))
        if best is None or value < best[0]:
            best = (value, perm)
    order = best[1] if best else ()
    return Ordering(order, wpl_terms(order, start, dist, rel, alpha))


def wpl_exact(start: FloatArray, dist: FloatArray, rel: FloatArray, alpha: float) -> Ordering:
    """Minimum-WPL order by the subset dynamic program (exact; n ≤ MAX_EXACT_STOPS)."""
    n = _check(start, dist, rel)
    if n == 0:
        return Ordering((), ())
    if n > MAX_EXACT_STOPS:
        raise ValueError(f"{n} stops exceed the exact planner's limit of {MAX_EXACT_STOPS}")
    weight = 1.0 / (1.0 + alpha * rel)
    full = (1 << n) - 1
    cost = np.full((1 << n, n), np.inf)
    parent = np.full((1 << n, n), -1, dtype=np.int8)
    for k in range(n):
        cost[1 << k, k] = start[k] * weight[k]

    masks = np.arange(1 << n, dtype=np.int64)
    popcount = np.zeros(1 << n, dtype=np.int64)
    for k in range(n):
        popcount += (masks >> k) & 1
    # Leg j→k entering position c-1 costs dist[j, k] · weight[k] / 2^(c-1).
    for c in range(2, n + 1):
        layer = masks[popcount == c]
        scale = 0.5 ** (c - 1)
        for k in range(n):
            ends = layer[((layer >> k) & 1) == 1]
            prev = ends ^ (1 << k)
            cand = cost[prev] + dist[:, k] * (weight[k] * scale)
            best = np.argmin(cand, axis=1)
            cost[ends, k] = cand[np.arange(len(ends)), best]
            parent[ends, k] = best

    last = int(np.argmin(cost[full]))
    order: list[int] = []
    mask = full
    while last >= 0:
        order.append(last)
        prev_last = int(parent[mask, last])
        mask ^= 1 << last
        last = prev_last if mask else -1
    order.reverse()
    return Ordering(tuple(order), wpl_terms(order, start, dist, rel, alpha))


def wpl_plan(start: FloatArray, dist: FloatArray, rel: FloatArray, alpha: float) -> Ordering:
    """Minimum-WPL order: exact up to MAX_EXACT_STOPS stops.

    Beyond that, the exact DP runs over the MAX_EXACT_STOPS stops with the smallest first-leg
    term and the rest follow greedily; their discount is below 2^-18, so they barely move the
    objective. The result says ``exact=False`` so the plan event records it.
    """
    n = _check(start, dist, rel)
    if n <= MAX_EXACT_STOPS:
        return wpl_exact(start, dist, rel, alpha)
    attract = start / (1.0 + alpha * rel)
    head = sorted(np.argsort(attract, kind="stable")[:MAX_EXACT_STOPS].tolist())
    sub = wpl_exact(start[head], dist[np.ix_(head, head)], rel[head], alpha)
    order = [head[i] for i in sub.order]
    rest = [k for k in range(n) if k not in set(order)]
    while rest:
        here = order[-1]
        nxt = min(rest, key=lambda k: (dist[here, k] / (1.0 + alpha * rel[k]), k))
        order.append(nxt)
        rest.remove(nxt)
    return Ordering(tuple(order), wpl_terms(order, start, dist, rel, alpha), exact=False)


def relation_order(start: FloatArray, dist: FloatArray, rel: FloatArray, alpha: float) -> Ordering:
    """RVP: highest relation value first; ties (instances of one class) nearest-first, greedily.

    The terms reported are Eq. 3's with the given α, so plans of all methods compare on one scale.
    """
    n = _check(start, dist, rel)
    order: list[int] = []
    rest = list(range(n))
    while rest:
        top = max(float(rel[k]) for k in rest)
        tied = [k for k in rest if float(rel[k]) == top]
        legs = start if not order else dist[order[-1]]
        nxt = min(tied, key=lambda k: (float(legs[k]), k))
        order.append(nxt)
        rest.remove(nxt)
    return Ordering(tuple(order), wpl_terms(order, start, dist, rel, alpha))


# -- expected path length ------------------------------------------------------------------------


def epl_probabilities(rel: FloatArray, rest_mass: float) -> FloatArray:
    """P(target at stop i), with ``rest_mass`` of relation mass in the rooms still to come.

    The model: the target is at exactly one candidate of the home, with probability proportional to
    its Rel. All-zero mass (nothing related anywhere) gives every stop of the room the same chance.
    """
    total = float(rel.sum()) + max(rest_mass, 0.0)
    if total <= 0.0:
        return np.full(len(rel), 1.0 / max(len(rel), 1))
    return np.asarray(rel / total, dtype=np.float64)


def epl_terms(
    order: Sequence[int],
    start: FloatArray,
    dist: FloatArray,
    prob: FloatArray,
    to_exit: FloatArray | None,
) -> tuple[float, ...]:
    """Expected metres of each leg of an order: a leg is walked only if the target was not at any
    earlier stop; the last term is the walk on to the next room, if the room held nothing."""
    terms: list[float] = []
    remaining = 1.0
    prev: int | None = None
    for k in order:
        leg = start[k] if prev is None else dist[prev, k]
        terms.append(float(leg) * remaining)
        remaining -= float(prob[k])
        prev = k
    if to_exit is not None and prev is not None:
        terms.append(float(to_exit[prev]) * max(remaining, 0.0))
    return tuple(terms)


def epl_enumerate(
    start: FloatArray, dist: FloatArray, prob: FloatArray, to_exit: FloatArray | None = None
) -> Ordering:
    """Minimum expected path length by trying all n! orders (the reference for the DP)."""
    n = len(start)
    best: tuple[float, tuple[int, ...]] | None = None
    for perm in itertools.permutations(range(n)):
        value = math.fsum(epl_terms(perm, start, dist, prob, to_exit))
        if best is None or value < best[0] - 1e-12:
            best = (value, perm)
    order = best[1] if best else ()
    return Ordering(order, epl_terms(order, start, dist, prob, to_exit))


#: Up to this many stops the DP's index arrays are kept between calls (every size up to 12:
#: about 2 MB); beyond, each call makes its own (n = 18 would keep some 60 MB).
CACHED_DP_STOPS = 12
IntArray = npt.NDArray[np.int64]


@functools.cache
def _dp_steps(n: int) -> tuple[list[IntArray], list[tuple[int, IntArray, IntArray, IntArray]]]:
    """What :func:`epl_exact`'s DP over ``n`` stops indexes, which depends on ``n`` alone: each
    stop's bit of every subset, and per popcount layer (ascending) and last stop k, the subsets
    of the layer holding k, those without k, and their row numbers."""
    masks = np.arange(1 << n, dtype=np.int64)
    bits = [(masks >> k) & 1 for k in range(n)]
    popcount = np.zeros(1 << n, dtype=np.int64)
    for bit in bits:
        popcount += bit
    steps = []
    for c in range(2, n + 1):
        layer = masks[popcount == c]
        for k in range(n):
            ends = layer[((layer >> k) & 1) == 1]
            steps.append((k, ends, ends ^ (1 << k), np.arange(len(ends))))
    for array in [*bits, *(a for step in steps for a in step[1:])]:
        array.flags.writeable = False  # shared between calls
    return bits, steps


def epl_exact(
    start: FloatArray, dist: FloatArray, prob: FloatArray, to_exit: FloatArray | None = None
) -> Ordering:
    """Minimum expected path length by a subset DP: leg j→k after visiting set S costs
    dist[j, k] · (1 − P(S)); it depends on S only through P(S), so (S, last) is a sufficient state."""
    n = len(start)
    if dist.shape != (n, n) or prob.shape != (n,):
        raise ValueError(f"shape mismatch: start {start.shape}, dist {dist.shape}, p {prob.shape}")
    if n == 0:
        return Ordering((), ())
    if n > MAX_EXACT_STOPS:
        raise ValueError(f"{n} stops exceed the exact planner's limit of {MAX_EXACT_STOPS}")
    full = (1 << n) - 1
    bits, steps = _dp_steps(n) if n <= CACHED_DP_STOPS else _dp_steps.__wrapped__(n)
    mass = np.zeros(1 << n)
    for k in range(n):
        mass += bits[k] * prob[k]
    remaining = np.maximum(1.0 - mass, 0.0)
    cost = np.full((1 << n, n), np.inf)
    parent = np.full((1 << n, n), -1, dtype=np.int8)
    for k in range(n):
        cost[1 << k, k] = start[k]
    legs = [dist[:, k][None, :] for k in range(n)]
    for k, ends, prev, rows in steps:
        cand = cost[prev] + legs[k] * remaining[prev][:, None]
        best = np.argmin(cand, axis=1)
        cost[ends, k] = cand[rows, best]
        parent[ends, k] = best
    final = cost[full].copy()
    if to_exit is not None:
        final += to_exit * remaining[full]
    last = int(np.argmin(final))
    order: list[int] = []
    mask = full
    while last >= 0:
        order.append(last)
        prev_last = int(parent[mask, last])
        mask ^= 1 << last
        last = prev_last if mask else -1
    order.reverse()
    return Ordering(tuple(order), epl_terms(order, start, dist, prob, to_exit))


# -- planners as plug-ins ------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class PlanProblem:
    """Everything a stop planner may use to order the candidates of one room.

    ``start``: metres from the robot to each stop; ``dist``: between stops; ``rel``: Rel(target, s)
    per stop; ``to_exit``: metres from each stop to the entry of the next room to search (None in
    the last room); ``rest_mass``: the summed Rel of the candidates in the rooms still to come.
    """

    start: FloatArray
    dist: FloatArray
    rel: FloatArray
    to_exit: FloatArray | None = None
    rest_mass: float = 0.0


class StopPlanner(Protocol):
    """Orders the stops of one room (the seam new planners plug into)."""

    @property
    def name(self) -> str: ...

    @property
    def alpha(self) -> float: ...

    def plan(self, problem: PlanProblem) -> Ordering: ...


@dataclass(frozen=True)
class WplPlanner:
    """The paper's Eq. 3 (SDP is this with α = 0)."""

    alpha: float = 10.0
    name: str = "wpl"

    def plan(self, problem: PlanProblem) -> Ordering:
        return wpl_plan(problem.start, problem.dist, problem.rel, self.alpha)


@dataclass(frozen=True)
class RelationOrderPlanner:
    """RVP: highest Rel first (terms reported on Eq. 3's scale with ``alpha``)."""

    alpha: float = 10.0
    name: str = "rvp"

    def plan(self, problem: PlanProblem) -> Ordering:
        return relation_order(problem.start, problem.dist, problem.rel, self.alpha)


@dataclass(frozen=True)
class ExpectedPathPlanner:
    """Minimum expected metres until the target is found, with P(stop) ∝ Rel over the stops of this
    room and of the rooms still to come (``rest_mass``), counting the walk on to the next room.

    Exact up to MAX_EXACT_STOPS; beyond, the DP runs over the stops most likely per metre and the
    rest follow greedily (``exact=False``).
    """

    name: str = "epl"
    alpha: float = 0.0

    def plan(self, problem: PlanProblem) -> Ordering:
        prob = epl_probabilities(problem.rel, problem.rest_mass)
        return epl_plan(problem.start, problem.dist, prob, problem.to_exit)


def epl_plan(
    start: FloatArray,
    dist: FloatArray,
    prob: FloatArray,
    to_exit: FloatArray | None = None,
    max_exact: int = MAX_EXACT_STOPS,
) -> Ordering:
    """Minimum expected path length: exact (:func:`epl_exact`) up to ``max_exact`` stops.

    Beyond, the DP runs over the ``max_exact`` stops most likely per metre from here and the rest
    follow greedily by probability per metre (``exact=False``): the bound is on the size of the
    exact problem, not on the gap, which the caller measures (benchmarks/decisions.py).
    """
    n = len(start)
    if n <= max_exact:
        return epl_exact(start, dist, prob, to_exit)
    ratio = start / np.maximum(prob, 1e-12)
    head = sorted(np.argsort(ratio, kind="stable")[:max_exact].tolist())
    sub = epl_exact(start[head], dist[np.ix_(head, head)], prob[head], to_exit=None)
    order = [head[i] for i in sub.order]
    rest = [k for k in range(n) if k not in set(order)]
    while rest:
        here = order[-1]
        nxt = min(rest, key=lambda k: (dist[here, k] / max(prob[k], 1e-12), k))
        order.append(nxt)
        rest.remove(nxt)
    return Ordering(tuple(order), epl_terms(order, start, dist, prob, to_exit), exact=False)
