"""The belief over places: a probability distribution per target, learned from episodes,
conditioned on today's looks and sightings, quick to follow a habit that moved."""

from __future__ import annotations

import json
import math

import pytest

from objsearch.agent.belief import (
    ELSEWHERE,
    MISS,
    MOVED_TODAY,
    TYPICAL_MASK_PX,
    PlaceBelief,
    reports_model,
)
from objsearch.agent.catalogue import (
    Detected,
    PlanarPose,
    Support,
    TaskEnded,
    TaskStarted,
    ViewTaken,
)
from objsearch.agent.detector_model import preset

from .belief_logs import Log, fold_into


def _belief(log: Log) -> PlaceBelief:
    return fold_into(PlaceBelief(prior_strength=1.0, half_life_scenes=3.0), log)


def test_the_prior_is_a_distribution_over_places_and_elsewhere() -> None:
    dist = _belief(Log()).distribution("Cup")
    assert math.isclose(math.fsum(dist.values()), 1.0)
    assert dist["counter-a"] == pytest.approx(dist["counter-b"])
    assert dist["table"] == pytest.approx(dist["counter-a"] / 2)  # Rel₀ 0.25 against 0.5
    assert dist[ELSEWHERE] == pytest.approx(0.05)
    assert "shelf" not in dist  # Rel₀ 0 and never seen there: no candidate


def test_room_probabilities_are_sums_of_place_probabilities() -> None:
    belief = _belief(Log())
    dist, rooms = belief.distribution("Cup"), belief.rooms("Cup")
    assert rooms["kitchen"] == pytest.approx(dist["counter-a"] + dist["counter-b"])
    assert math.isclose(math.fsum(rooms.values()) + dist[ELSEWHERE], 1.0)


def test_a_usual_place_becomes_the_most_likely() -> None:
    log = Log()
    for scene in range(1, 21):  # at counter-a three days in four, at the table the fourth
        log.search("Cup", scene, found="table" if scene % 4 == 0 else "counter-a")
    log.search("Apple", 21, found="counter-b")  # opens scene 21: nothing of the Cup seen yet
    dist = _belief(log).distribution("Cup")
    # Yesterday (scene 20) it was on the table: that counts, but the habit counts more.
    assert dist["counter-a"] > 0.5 > dist["table"] > 0.1
    assert dist["counter-b"] < 0.05


def test_a_moved_habit_takes_over_within_three_days() -> None:
    log = Log()
    for scene in range(1, 11):
        log.search("Cup", scene, found="counter-a")
    for scene in range(11, 14):
        log.search("Cup", scene, found="table")
    log.search("Apple", 14, found="counter-b")
    dist = _belief(log).distribution("Cup")
    assert dist["table"] > dist["counter-a"]
    assert dist["table"] > 0.5


def test_what_another_search_saw_today_decides_and_looks_without_it_count_against() -> None:
    log = Log()
    for scene in range(1, 6):
        log.search("Cup", scene, found="counter-a")
    log.search("Apple", 6, looks=("counter-b",), found="table", also_seen={"Cup": "table"})
    belief = _belief(log)
    assert belief.distribution("Cup")["table"] > 1 - MOVED_TODAY
    # The Apple was not on counter-b (a look without it) nor anywhere it was not found later.
    log.search("Apple", 7, looks=("counter-a",))
    log.search("Cup", 7, found="counter-a")
    before = _belief(log).distribution("Apple")
    log.events.pop()  # task_ended of the Cup's search: keep scene 7 open
    log.search("Apple", 7, looks=("counter-a",), found="table")
    dist = _belief(log).distribution("Apple")
    assert dist["table"] > 1 - MOVED_TODAY
    # Two looks at counter-a in scene 7 without the Apple (its own search's, the Cup's).
    assert before["counter-a"] / before["counter-b"] == pytest.approx(MISS**2)


def test_a_search_plans_on_the_values_at_its_start() -> None:
    log = Log()
    log.search("Cup", 1, found="counter-a")
    log.events.pop()  # the task has not ended: its looks and sightings do not count yet
    belief = _belief(log)
    assert belief.distribution("Cup")["counter-a"] < 0.5
    log.add(TaskEnded(target="Cup", success=True, path_length=1.0), "t1")
    assert _belief(log).distribution("Cup")["counter-a"] > 1 - MOVED_TODAY


def test_a_search_that_never_found_its_target_spreads_one_day_over_what_it_did_not_rule_out() -> (
    None
):
    log = Log()
    log.search("Cup", 1, looks=("counter-a", "counter-b"))
    log.search("Apple", 2, found="table")
    belief = _belief(log)
    long = belief.long["Cup"]
    assert long.total == pytest.approx(1.0)
    assert long.at["table"] > long.at["counter-a"]  # the looked-at counters are less likely


def test_scenes_without_number_are_episodes_of_one_task() -> None:
    log = Log()
    log.search("Cup", None, found="counter-a")
    log.search("Cup", None, found="counter-a")
    belief = _belief(log)
    assert belief.episodes == 2
    assert belief.long["Cup"].at["counter-a"] == pytest.approx(2.0)


def test_a_snapshot_restores_the_same_belief_and_folds_on_the_same() -> None:
    log = Log()
    for scene in range(1, 5):
        log.search("Cup", scene, looks=("counter-b",), found="counter-a")
    belief = _belief(log)
    again = PlaceBelief.from_snapshot(json.loads(json.dumps(belief.to_snapshot())), 0)
    assert again.distribution("Cup") == belief.distribution("Cup")
    more = Log(list(log.events), log.tasks)
    more.search("Cup", 5, found="table")
    for event in more.events[len(log.events) :]:
        again.apply(event)
    assert again.distribution("Cup") == _belief(more).distribution("Cup")


def _search_with_a_report(log: Log, scene: int, reported: str, score: float) -> None:
    """A Cup search that looks at counter-b twice; the detector reports ``reported`` there once,
    too unsure to take (not accepted)."""
    log.tasks += 1
    task = f"t{log.tasks}"
    pose = PlanarPose(x=0.0, y=0.0, yaw=0.0)
    log.add(TaskStarted(target="Cup", start="s", pose=pose, scene=scene, clock=None), task)
    for _ in range(2):
        log.add(ViewTaken(pose=pose, pitch=0.5, static_id="counter-b", reason="look"), task)
    log.add(
        Detected(
            object_class=reported,
            instance_id=f"{reported}|1",
            mask_area=2000.0,
            position=(0.0, 0.0, 0.9),
            accepted=False,
            support=Support(static_id="counter-b", static_class="CounterTop", at=True),
            score=score,
            classes=(),
        ),
        task,
    )
    log.add(TaskEnded(target="Cup", success=False, path_length=1.0), task)


@pytest.mark.parametrize("reports", ["misses", "evidence"])
def test_a_report_that_was_no_sighting_counts_for_its_place_with_reports_evidence(
    reports: str,
) -> None:
    log = Log()
    log.search("Cup", 1, found="counter-a")
    _search_with_a_report(log, 2, "Apple", 0.9)
    belief = PlaceBelief(prior_strength=1.0, half_life_scenes=3.0)
    model = preset("realistic", reports=reports)
    # What run_started sets from the run's params.perception (the log here has none).
    belief.today.reports_model = reports_model(model.params())
    dist = fold_into(belief, log).distribution("Apple")
    ratio = dist["counter-b"] / dist["counter-a"]  # equal before scene 2 (both CounterTop)
    if reports == "misses":
        assert ratio == pytest.approx(MISS**2)  # two views without a sighting: two misses
    else:
        # One view a miss, the other the report's likelihood ratio: more likely than before.
        assert ratio == pytest.approx(MISS * model.look_ratio(TYPICAL_MASK_PX, 0.9))
        assert ratio > 1.0
        again = PlaceBelief.from_snapshot(json.loads(json.dumps(belief.to_snapshot())), 0)
        assert again.distribution("Apple") == dist
    # The Cup (not reported) is missed twice at counter-b either way.
    cup = belief.today.condition("Cup", {"counter-a": 0.5, "counter-b": 0.5})
    assert cup["counter-b"] / cup["counter-a"] == pytest.approx(MISS**2)


def test_a_run_spec_that_names_no_reports_folds_reports_as_misses() -> None:
    old = preset("realistic", reports="misses").params()
    assert "reports" not in old  # a run spec from before the option
    assert reports_model(old) is None
    assert reports_model(preset("realistic").params()) is not None  # the preset's default
    assert reports_model(None) is None  # perfect
