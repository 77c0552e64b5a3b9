"""The pooled belief that knows the hour: the home's mixture of the three components, learned
from every class's episodes, offered to each class's model average as a fourth component."""

from __future__ import annotations

import json
import math

import pytest

from objsearch.agent.catalogue import DayClock
from objsearch.agent.routine_belief import (
    POOLED_COMPONENTS,
    PooledRoutineBelief,
    RoutineBelief,
    mixture,
    softmax,
)

from .belief_logs import Log, fold_into

MORNING = DayClock(weekday=1, minute=7 * 60 + 30)
EVENING = DayClock(weekday=1, minute=18 * 60 + 30)
SATURDAY_MORNING = DayClock(weekday=5, minute=9 * 60)


def _pooled(log: Log) -> PooledRoutineBelief:
    belief = fold_into(PooledRoutineBelief(prior_strength=1.0, half_life_scenes=3.0), log)
    assert isinstance(belief, PooledRoutineBelief)
    return belief


def _routine(log: Log) -> RoutineBelief:
    belief = fold_into(RoutineBelief(prior_strength=1.0, half_life_scenes=3.0), log)
    assert isinstance(belief, RoutineBelief)
    return belief


def _home_with_routines(days: int, *, cup_days: int | None = None) -> Log:
    """Mornings and evenings: the Apple on counter-b in the morning and on the shelf in the
    evening (``days`` days), the Cup on counter-a / the table (``cup_days``, all days if None),
    one scene per half day, both classes seen in every scene of their days."""
    log = Log()
    scene = 0
    for day in range(days):
        for clock, apple, cup in ((MORNING, "counter-b", "counter-a"), (EVENING, "shelf", "table")):
            scene += 1
            seen = {} if cup_days is not None and day >= cup_days else {"Cup": cup}
            log.search("Apple", scene, found=apple, also_seen=seen, clock=clock)
    return log


def _wandering_cup() -> Log:
    """No routine: the Cup stays a few scenes, then moves, whatever the hour."""
    log = Log()
    clocks = (MORNING, DayClock(weekday=1, minute=13 * 60), EVENING, SATURDAY_MORNING)
    places = ("counter-a", "table", "shelf", "counter-b")
    for scene in range(1, 41):
        log.search("Cup", scene, found=places[(scene // 3) % 4], clock=clocks[scene % 4])
    log.search("Apple", 41, found="counter-b", clock=clocks[1])
    return log


def test_mixture_and_softmax_by_hand() -> None:
    mixed = mixture((0.25, 0.75), ({"a": 1.0}, {"a": 0.2, "b": 0.8}))
    assert mixed == pytest.approx({"a": 0.25 + 0.75 * 0.2, "b": 0.75 * 0.8})
    assert softmax((0.0, 0.0, 0.0, 0.0)) == pytest.approx((0.25,) * 4)
    w = softmax((0.0, math.log(3.0)))
    assert w == pytest.approx((0.25, 0.75))


def test_the_home_mixture_leans_on_the_slots_where_every_class_keeps_a_routine() -> None:
    belief = _pooled(_home_with_routines(8))
    blind, slot, slot_day = belief.pooled
    assert math.isclose(blind + slot + slot_day, 1.0)
    assert slot + slot_day > 2 * blind
    # One move per episode with a clock, whatever the number of classes in it.
    assert belief.pooled_episodes == 2 * 8 - 1  # the last episode is still open


def test_the_home_mixture_leans_on_the_time_blind_belief_without_routines() -> None:
    belief = _pooled(_wandering_cup())
    blind, slot, slot_day = belief.pooled
    assert blind > max(slot, slot_day)
    weights = belief.component_weights("Cup")
    assert list(weights) == list(POOLED_COMPONENTS)
    assert weights["blind"] > 0.5


def test_the_home_mixture_is_learned_from_every_class() -> None:
    # Two days of the Apple's routine: with the Cup's routine beside it for eight days the
    # home's mixture trusts the slots more than the Apple's two days alone make it.
    alone = _pooled(_home_with_routines(2, cup_days=0))
    beside = _home_with_routines(8)
    # The same two Apple days at the end, after the Cup's eight.
    log = Log(events=list(beside.events), tasks=beside.tasks)
    scene = 16
    for clock, apple in ((MORNING, "counter-b"), (EVENING, "shelf")) * 2:
        scene += 1
        log.search("Apple", scene, found=apple, also_seen={"Cup": "shelf"}, clock=clock)
    log.search("Vase", scene + 1, clock=MORNING)  # a new morning, nothing of it seen
    pooled = _pooled(log)
    assert pooled.pooled[1] + pooled.pooled[2] > alone.pooled[1] + alone.pooled[2]
    # The Apple's fourth component is the home's mixture of its three, by hand.
    three = pooled._components("Apple", MORNING)
    by_hand: dict[str, float] = {}
    for w, pred in zip(pooled.pooled, three, strict=True):
        for place, p in pred.items():
            by_hand[place] = by_hand.get(place, 0.0) + w * p
    assert pooled._four("Apple", MORNING)[3] == pytest.approx(by_hand, abs=1e-12)
    assert pooled.distribution("Apple")["counter-b"] > 0.9


def test_without_a_time_of_day_it_is_the_time_blind_belief() -> None:
    log = Log()
    for scene in range(1, 13):
        log.search("Cup", scene, found="table" if scene % 3 == 0 else "counter-a")
    pooled, routine = _pooled(log), _routine(log)
    assert not pooled.knows_hours and pooled.pooled_episodes == 0
    assert pooled.distribution("Cup") == pytest.approx(routine.distribution("Cup"), abs=1e-12)


def test_the_same_log_folds_to_the_same_belief() -> None:
    log = _home_with_routines(5)
    first, second = _pooled(log), _pooled(log)
    assert first.to_snapshot() == second.to_snapshot()
    for clock in (MORNING, EVENING, SATURDAY_MORNING):
        assert first.distribution_at("Apple", clock) == second.distribution_at("Apple", clock)


def test_a_snapshot_restores_the_same_belief_and_folds_on_the_same() -> None:
    log = _home_with_routines(5)
    head = Log(events=log.events[: len(log.events) // 2 + 1])
    first = _pooled(head)
    restored = PooledRoutineBelief.from_snapshot(
        json.loads(json.dumps(first.to_snapshot())), first.last_seq
    )
    assert isinstance(restored, PooledRoutineBelief)
    assert restored.to_snapshot() == first.to_snapshot()
    for event in log.events[len(head.events) :]:
        restored.apply(event)
    whole = _pooled(log)
    assert restored.to_snapshot() == whole.to_snapshot()
    for clock in (MORNING, EVENING, SATURDAY_MORNING):
        assert restored.distribution_at("Apple", clock) == whole.distribution_at("Apple", clock)
