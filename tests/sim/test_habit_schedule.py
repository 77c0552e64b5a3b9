"""Habit schedules: seeded, 30 scenes, usual places most days, drawn from valid placements."""

from __future__ import annotations

import math

import pytest

from objsearch.agent.home import load_home
from objsearch.sim.habit_schedule import (
    HABIT_SCENES,
    P_USUAL,
    habit_distribution,
    habit_schedule,
    habits,
)
from objsearch.sim.schedule_names import load_schedule
from objsearch.sim.stats_schedule import PlacementStats

RECEPTACLE_ALIAS = {"SinkBasin": "Sink", "BathtubBasin": "Bathtub"}


def test_seeded_and_resolved_by_name() -> None:
    home = load_home("ithor-01")
    a = habit_schedule(home, 0)
    assert a.scenes == load_schedule(home, "habit-0").scenes
    assert a.scenes != habit_schedule(home, 1).scenes
    assert sorted(a.scenes) == list(range(1, HABIT_SCENES + 1))


def test_objects_are_mostly_at_their_usual_place_and_only_where_valid() -> None:
    stats = PlacementStats.load()
    usual = total = 0
    for name in ("ithor-02", "procthor-01"):
        home = load_home(name)
        table = habits(home, 0)
        for placements in habit_schedule(home, 0).scenes.values():
            for p in placements.values():
                assert p.support is not None
                s = home.statics[p.support]
                assert (
                    stats.counts[p.cls].get(RECEPTACLE_ALIAS.get(s.thor_type, s.thor_type), 0) > 0
                )
                usual += p.support == table[p.cls].usual
                total += 1
    # The usual place also wins some of the 'anywhere' draws: at least P_USUAL, within noise.
    assert P_USUAL - 0.08 < usual / total < P_USUAL + 0.2


@pytest.mark.parametrize("name", ["ithor-03", "procthor-02"])
def test_distribution_sums_to_one_and_matches_the_draws(name: str) -> None:
    home = load_home(name)
    dist = habit_distribution(home, 2)
    for per in dist.values():
        assert math.isclose(sum(per.values()), 1.0)
    schedule = habit_schedule(home, 2, scenes=400)
    cls = sorted(dist)[0]
    hits = sum(
        p.support == max(dist[cls], key=dist[cls].__getitem__)
        for placements in schedule.scenes.values()
        for p in placements.values()
        if p.cls == cls
    )
    assert abs(hits / 400 - max(dist[cls].values())) < 0.07
