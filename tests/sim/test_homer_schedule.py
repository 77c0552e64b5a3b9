"""HOMER schedules: routines measured in the HOMER households, laid onto our homes."""

from __future__ import annotations

import math

import pytest

from objsearch.agent.home import load_home
from objsearch.pipeline import homer as converter
from objsearch.sim import routine_schedule
from objsearch.sim.distribution_oracle import (
    DistributionOracle,
    SlotOracle,
    schedule_distribution,
    time_blind_distribution,
    time_of_day_distribution,
)
from objsearch.sim.homer_schedule import (
    HOMER_SCENES,
    HomerRoutines,
    homer_schedule,
    homer_slot_distribution,
    laid_routines,
)
from objsearch.sim.schedule_names import load_schedule, schedule_clock
from objsearch.sim.stats_schedule import PlacementStats, _receptacle_type


def test_the_converter_counts_the_schedules_times_of_day() -> None:
    assert converter.SLOT_MINUTES == routine_schedule.SLOT_MINUTES


def test_seeded_and_resolved_by_name() -> None:
    home = load_home("ithor-01")
    a = homer_schedule(home, 0, scenes=8)
    assert a.name == "homer-0"
    assert a.scenes == load_schedule(home, "homer-0", scenes=8).scenes
    assert a.scenes != homer_schedule(home, 1, scenes=8).scenes
    assert sorted(homer_schedule(home, 0).scenes) == list(range(1, HOMER_SCENES + 1))
    assert schedule_clock("homer-0", 2) == routine_schedule.scene_clock(2)


def test_targets_keep_their_homer_counterparts_routines() -> None:
    homer = HomerRoutines.load()
    home = load_home("procthor-01")
    stats = PlacementStats.load()
    for seed in range(3):
        for cls, laid in laid_routines(home, seed).items():
            counterparts = homer.target_objects.get(cls, ())
            assert laid.routine.obj in counterparts if counterparts else True
            for node, sid in laid.statics.items():
                # Every place is one the class is put on in AI2-THOR, and a mapped HOMER place
                # is a static of its type whenever the class goes there.
                thor = _receptacle_type(home.statics[sid])
                assert stats.counts[cls].get(thor, 0) > 0
                mapped = homer.place_types.get(laid.routine.places[node])
                if mapped is not None and stats.counts[cls].get(mapped, 0) > 0:
                    assert thor == mapped or not any(
                        _receptacle_type(s) == mapped for s in home.statics.values()
                    )
    assert set(homer.target_objects) == {"Apple", "Bowl", "Cup"}


def test_scenes_follow_the_slots_counts() -> None:
    home = load_home("ithor-01")
    schedule = homer_schedule(home, 0)
    slots = [homer_slot_distribution(home, 0, k) for k in range(4)]
    hits = expected = total = 0.0
    for scene, placements in schedule.scenes.items():
        dist = slots[(scene - 1) % 4]
        for p in placements.values():
            top = max(dist[p.cls], key=dist[p.cls].__getitem__)
            hits += p.support == top
            expected += dist[p.cls][top]
            total += 1
    # Visibility redraws move a few placements off their drawn place.
    assert abs(hits - expected) / total < 0.06


def test_the_oracles_know_the_slot_and_the_day() -> None:
    home = load_home("ithor-01")
    blind = time_blind_distribution(home, "homer", 0, 2)
    assert schedule_distribution("ithor-01", "homer-0") == blind
    evening = time_of_day_distribution(home, "homer", 0, 2, False, 2)
    assert evening != blind
    for per in blind.values():
        assert math.isclose(sum(per.values()), 1.0)
    week, slot = DistributionOracle(), SlotOracle()
    for oracle in (week, slot):
        oracle._load("ithor-01", "homer-0")
        oracle.today.key = ("scene", 4 * 16 + 3)  # day 16, evening
    for cls in ("Apple", "Cup"):
        for sid, s in home.statics.items():
            assert slot.instance_rel(cls, sid, s.cls) == pytest.approx(evening[cls].get(sid, 0.0))
            assert week.instance_rel(cls, sid, s.cls) == pytest.approx(blind[cls].get(sid, 0.0))
