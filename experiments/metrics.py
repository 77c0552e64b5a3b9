"""Metrics of a set of searches: mean path length, success rate, SPL and the oracle ratio.

- **SPL** (Anderson et al. 2018): mean over searches of S·ℓ/max(p, ℓ), S = 1 on success, ℓ the oracle
  length (shortest walk to the nearest viewpoint of the closest instance of the target), p the path
  walked; a search starting where the oracle ends (ℓ = 0) scores 1 if found with p = 0.
- **Oracle ratio**: Σ p / Σ ℓ — how many times the walk of a robot that knew where the object was.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterable, Sequence
from typing import Any, Protocol


class TrialLike(Protocol):
    @property
    def success(self) -> bool: ...
    @property
    def path_length(self) -> float: ...
    @property
    def oracle_length(self) -> float: ...


def spl_term(t: TrialLike) -> float:
    if not t.success:
        return 0.0
    denom = max(t.path_length, t.oracle_length)
    return 1.0 if denom <= 0 else t.oracle_length / denom


def summarise(trials: Iterable[TrialLike]) -> dict[str, Any]:
    ts: Sequence[TrialLike] = list(trials)
    if not ts:
        return {"n": 0}
    path = math.fsum(t.path_length for t in ts)
    oracle = math.fsum(t.oracle_length for t in ts)
    return {
        "n": len(ts),
        "mean_path_length": path / len(ts),
        "success_rate": sum(t.success for t in ts) / len(ts),
        "spl": statistics.fmean(spl_term(t) for t in ts),
        "oracle_ratio": path / oracle if oracle > 0 else math.nan,
        "mean_oracle_length": oracle / len(ts),
    }


def mean_std(values: Sequence[float]) -> tuple[float, float]:
    if not values:
        return (math.nan, math.nan)
    return statistics.fmean(values), statistics.stdev(values) if len(values) > 1 else 0.0
