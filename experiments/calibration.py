"""How well the belief's probabilities are calibrated: its forecast at the start of each search
against where the search found the target.

Any log can be scored: it is folded with the belief (:data:`~objsearch.agent.strategies.BELIEF`)
as a counterfactual, exactly as ``objsearch where`` answers, so the forecast is what ``where``
would have said just before the search. A search that never found its target has no outcome and
is left out.

- **ECE** (expected calibration error, top-label, 10 equal-width bins): over searches, the
  |accuracy − confidence| of the most likely place, weighted by the bin's share of searches;
- **Brier score**: Σ over places (and elsewhere) of (P(place) − [found there])², per search.
- **ECE over every place** (docs/protocol-perception.md): the same bins over every (search,
  place) prediction (:func:`place_pairs`), each place's probability against whether the target
  was found there.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from objsearch.agent.belief import ELSEWHERE, PlaceBelief
from objsearch.agent.catalogue import Detected, TaskStarted, decode
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import BELIEF, RelationSpec
from objsearch.events.projection import EventView

BINS = 10


@dataclass(frozen=True, slots=True)
class Forecast:
    """The belief's forecast for one search and where the target was found."""

    task_id: str
    top_p: float  # probability of the most likely place
    top_hit: bool  # the target was found there
    p_found: float  # probability the forecast gave the place it was found at
    brier: float
    #: The probabilities it gave every other place (where the target was not found): with
    #: ``p_found`` the (search, place) predictions of :func:`place_pairs`.
    others: tuple[float, ...] = ()


def forecasts(
    events: Iterable[EventView], belief: RelationSpec = BELIEF, data: Path | None = None
) -> dict[str, Forecast]:
    """Per task id that found its target, the forecast at its start of ``belief`` (the
    time-blind belief, or the one that knows the hour), over the home of the data folder
    ``data`` the run was on (None: ``datapaths.data_dir()``)."""
    state = AgentState(counterfactual=belief, data=data)
    out: dict[str, Forecast] = {}
    dist: Mapping[str, float] = {}
    target: str | None = None
    found: str | None = None
    for event in events:
        state.apply(event)
        kind = event.type
        task_id = getattr(event, "task_id", None)
        if kind == "task_started":
            model = state.graph()
            assert isinstance(model, PlaceBelief)
            target = decode(event, TaskStarted).target
            dist, found = model.distribution(target), None
        elif kind == "detection" and target is not None and found is None:
            detected = decode(event, Detected)
            if detected.accepted and detected.object_class == target:
                support = detected.support
                found = support.static_id if support is not None and support.at else ELSEWHERE
        elif kind == "task_ended" and task_id is not None and found is not None and dist:
            out[task_id] = _score(task_id, dist, found)
            target = None
    return out


def _score(task_id: str, dist: Mapping[str, float], found: str) -> Forecast:
    top = min(dist, key=lambda p: (-dist[p], p))
    brier = math.fsum((v - (1.0 if p == found else 0.0)) ** 2 for p, v in dist.items())
    if found not in dist:
        brier += 1.0
    others = tuple(v for p, v in sorted(dist.items()) if p != found)
    return Forecast(task_id, dist[top], top == found, dist.get(found, 0.0), brier, others)


def place_pairs(p_found: float, others: Iterable[float]) -> list[tuple[float, bool]]:
    """One search's (search, place) predictions as (probability, the target was there) pairs:
    the protocol's reading of ECE (docs/protocol-perception.md) bins every one of them, not only
    the top place's."""
    return [(p_found, True), *((p, False) for p in others)]


def ece(pairs: Sequence[tuple[float, bool]], bins: int = BINS) -> float:
    """Top-label expected calibration error of (confidence, hit) pairs."""
    if not pairs:
        return math.nan
    total = 0.0
    for b in range(bins):
        lo, hi = b / bins, (b + 1) / bins
        inside = [(p, h) for p, h in pairs if lo <= p < hi or (b == bins - 1 and p == 1.0)]
        if inside:
            confidence = math.fsum(p for p, _ in inside) / len(inside)
            accuracy = sum(h for _, h in inside) / len(inside)
            total += len(inside) / len(pairs) * abs(accuracy - confidence)
    return total


def reliability(pairs: Sequence[tuple[float, bool]], bins: int = BINS) -> list[dict[str, float]]:
    """Per non-empty bin: its range, searches, mean confidence and accuracy (a reliability plot)."""
    rows = []
    for b in range(bins):
        lo, hi = b / bins, (b + 1) / bins
        inside = [(p, h) for p, h in pairs if lo <= p < hi or (b == bins - 1 and p == 1.0)]
        if inside:
            rows.append(
                {
                    "low": lo,
                    "high": hi,
                    "n": len(inside),
                    "confidence": math.fsum(p for p, _ in inside) / len(inside),
                    "accuracy": sum(h for _, h in inside) / len(inside),
                }
            )
    return rows
