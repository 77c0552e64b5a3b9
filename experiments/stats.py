"""Spread over runs, stated honestly: a 95 % interval only over enough runs, else n and the range.

A run is one (home, schedule, seed) of a strategy; its searches are not independent (they share
a scene graph), so every interval here is over runs, never over searches. A percentile bootstrap
of a mean covers less than it says with few runs (with 2 runs its "interval" is just the two
values), so below :data:`MIN_RUNS` no interval is given: the text shows n and the range of the
runs instead, and says so.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: Fewest runs a 95 % interval is given for; fewer show n and the range (min–max) instead.
MIN_RUNS = 10
RESAMPLES = 10_000
SEED = 0
#: What each kind of spread is called in tables and legends.
CI = "95 % CI"
RANGE = "range"


@dataclass(frozen=True, slots=True)
class Spread:
    """The mean of ``n`` run values and either its 95 % bootstrap interval (``kind`` CI) or, with
    fewer than :data:`MIN_RUNS` runs, the runs' min and max (``kind`` range)."""

    n: int
    mean: float
    low: float
    high: float
    kind: str

    @property
    def is_interval(self) -> bool:
        return self.kind == CI

    def text(self, fmt: str = "+.2f") -> str:
        """``[-3.46, -3.07]`` for an interval; ``range [a, b], n = 2 (no CI: < 10 runs)``."""
        bounds = f"[{self.low:{fmt}}, {self.high:{fmt}}]"
        if self.is_interval:
            return bounds
        return f"{RANGE} {bounds}, n = {self.n} (no CI: < {MIN_RUNS} runs)"


def bootstrap_mean(
    values: Sequence[float], *, resamples: int = RESAMPLES, seed: int = SEED
) -> tuple[float, float]:
    """Percentile bootstrap 95 % interval of the mean of ``values`` (resampling with
    replacement, seeded: the same values give the same interval)."""
    data = np.asarray(values, dtype=np.float64)
    rng = np.random.default_rng(seed)
    means = data[rng.integers(0, len(data), size=(resamples, len(data)))].mean(axis=1)
    low, high = np.quantile(means, [0.025, 0.975])
    return float(low), float(high)


def spread(values: Sequence[float], *, resamples: int = RESAMPLES, seed: int = SEED) -> Spread:
    """The mean over runs with a 95 % interval when there are at least :data:`MIN_RUNS` runs,
    else with the runs' range (see the module doc)."""
    if not values:
        raise ValueError("no runs to summarise")
    mean = math.fsum(values) / len(values)
    if len(values) < MIN_RUNS:
        return Spread(len(values), mean, min(values), max(values), RANGE)
    low, high = bootstrap_mean(values, resamples=resamples, seed=seed)
    return Spread(len(values), mean, low, high, CI)


def method_note() -> str:
    """One sentence for a caption: how the spreads of a page were computed."""
    resamples = f"{RESAMPLES:,}".replace(",", " ")
    return (
        "Intervals are over runs (home, schedule, seed), not searches: a percentile bootstrap "
        f"95 % CI of the mean ({resamples} resamples, seed {SEED}) with at least {MIN_RUNS} "
        "runs; with fewer, no interval is given — n and the range of the runs are shown."
    )


__all__ = ["CI", "MIN_RUNS", "RANGE", "Spread", "bootstrap_mean", "method_note", "spread"]
