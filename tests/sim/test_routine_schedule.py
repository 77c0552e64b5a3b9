"""Routine schedules: where an object is depends on the slot of the day and the day type; every
seeded schedule's scenes are times of day, recorded in each search's ``task_started``."""

from __future__ import annotations

import math

import pytest

from objsearch.agent.home import load_home
from objsearch.sim.distribution_oracle import (
    DistributionOracle,
    SlotOracle,
    schedule_distribution,
    time_blind_distribution,
    time_of_day_distribution,
)
from objsearch.sim.routine_schedule import (
    P_USUAL,
    ROUTINE_DAYS,
    SCENES_PER_DAY,
    SLOT_MINUTES,
    WEEKEND,
    routine_schedule,
    routines_by_week,
    scene_clock,
    scene_day,
)
from objsearch.sim.schedule_names import load_schedule, schedule_clock


def test_scenes_are_four_times_a_day_from_a_monday_morning() -> None:
    assert scene_clock(1).weekday == 0 and scene_clock(1).minute == SLOT_MINUTES[0]
    assert scene_clock(4).minute == SLOT_MINUTES[3] and scene_clock(5).minute == SLOT_MINUTES[0]
    assert scene_clock(5).weekday == 1
    assert scene_clock(6 * SCENES_PER_DAY + 1).weekday == 6
    assert scene_clock(7 * SCENES_PER_DAY + 1).weekday == 0
    assert schedule_clock("habit-3", 5) == scene_clock(5)
    assert schedule_clock("table2", 5) is None and schedule_clock("routine-0", None) is None


def test_seeded_and_resolved_by_name() -> None:
    home = load_home("ithor-01")
    a = routine_schedule(home, 0, scenes=12)
    assert a.scenes == load_schedule(home, "routine-0", scenes=12).scenes
    assert a.scenes != routine_schedule(home, 1, scenes=12).scenes
    assert sorted(routine_schedule(home, 0).scenes) == list(
        range(1, ROUTINE_DAYS * SCENES_PER_DAY + 1)
    )


def test_objects_follow_the_slots_routine_most_of_the_time() -> None:
    home = load_home("procthor-01")
    weekly = routines_by_week(home, 0, 3)
    schedule = routine_schedule(home, 0)
    usual = total = 0
    for scene, placements in schedule.scenes.items():
        day = scene_day(scene)
        table = weekly[day // 7]
        slot = (scene - 1) % SCENES_PER_DAY
        for p in placements.values():
            usual += p.support == table[p.cls].usual(day % 7 in WEEKEND, slot)
            total += 1
    # Visibility redraws take some of the usual draws, 'anywhere' gives some back.
    assert P_USUAL - 0.12 < usual / total < P_USUAL + 0.15
    # And the slots differ: a routine, not one habit.
    assert any(len(set(r.weekday)) > 1 for r in weekly[0].values())


def test_the_blind_distribution_is_the_weeks_average_of_the_slots() -> None:
    home = load_home("ithor-01")
    blind = time_blind_distribution(home, "routine", 2, 0)
    for cls, per in blind.items():
        assert math.isclose(sum(per.values()), 1.0)
        monday_morning = time_of_day_distribution(home, "routine", 2, 0, False, 0)[cls]
        assert math.isclose(sum(monday_morning.values()), 1.0)
        # A slot knows its usual place better than the week does (unless every slot agrees).
        top = max(monday_morning, key=monday_morning.__getitem__)
        assert monday_morning[top] >= blind[cls].get(top, 0.0) - 1e-12
    # The oracle's knowledge follows the drift week by week.
    assert schedule_distribution("ithor-01", "routine-2", scene=1) == blind


def test_the_slot_oracle_knows_the_hour_and_the_distribution_oracle_does_not() -> None:
    home = load_home("ithor-01")
    saturday_evening = 5 * SCENES_PER_DAY + 3  # day 5 (a Saturday), slot 2
    blind, slot = DistributionOracle(), SlotOracle()
    for oracle in (blind, slot):
        oracle._load("ithor-01", "routine-0")
        oracle.today.key = ("scene", saturday_evening)
    exact = time_of_day_distribution(home, "routine", 0, 0, True, 2)
    week = time_blind_distribution(home, "routine", 0, 0)
    for cls in ("Cup", "Laptop"):
        for sid in home.statics:
            cls_of = home.statics[sid].cls
            assert slot.instance_rel(cls, sid, cls_of) == pytest.approx(exact[cls].get(sid, 0.0))
            assert blind.instance_rel(cls, sid, cls_of) == pytest.approx(week[cls].get(sid, 0.0))
