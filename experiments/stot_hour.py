"""The hour-of-day histogram ``routine-hour`` of ``bench stot`` forecasts with beyond the next step.

Issue 47's third pass (docs/results-stot.md, its amendment): ``routine-habit``'s habit has four
slots a day, so it cannot say *when* within a morning an object moves. ``routine-hour`` keeps
``routine-belief``'s forecast for the next step and, for a lookahead step further on, forecasts
each object's share of the observed steps at each parent in that step's hour of the day: every
observed step counts once (training and test days alike), with no prior, no smoothing and no
decay. An object never observed in that hour stays where it was last seen.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

MINUTES_A_DAY = 1440


def hour_of(minutes: int) -> int:
    """The hour of the day (0-23) of a time in minutes from the first day's midnight."""
    return (minutes % MINUTES_A_DAY) // 60


@dataclass
class HourHistogram:
    """Counts of each target's observed parent per hour of the day."""

    #: (target, hour) -> parent -> observed steps.
    counts: dict[tuple[str, int], dict[str, int]] = field(default_factory=dict)
    #: target -> its parent at its last observed step.
    last: dict[str, str] = field(default_factory=dict)

    def observe(self, minutes: int, parents: Mapping[str, str]) -> None:
        """One observed step at that time: each target's parent."""
        hour = hour_of(minutes)
        for target, parent in parents.items():
            at = self.counts.setdefault((target, hour), {})
            at[parent] = at.get(parent, 0) + 1
            self.last[target] = parent

    def forecast(self, target: str, minutes: int) -> dict[str, float]:
        """P(parent) of the target at that time: its share of the hour's observed steps (its last
        parent when the hour has none; empty before any observation)."""
        at = self.counts.get((target, hour_of(minutes)))
        if not at:
            last = self.last.get(target)
            return {} if last is None else {last: 1.0}
        n = sum(at.values())
        return {parent: count / n for parent, count in at.items()}
