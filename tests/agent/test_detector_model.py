"""The detector model the agent reasons with: presets, recall by size, what a score says."""

from __future__ import annotations

import math

import pytest

from objsearch.agent.detector_model import (
    LARGE_PX,
    MASK_RCNN_RECALL,
    SMALL_PX,
    PerceptionModel,
    preset,
)
from objsearch.agent.errors import ObjsearchError


def test_perfect_sees_everything_and_is_sure_of_it() -> None:
    model = preset("perfect")
    assert model.perfect and model == PerceptionModel()
    assert model.recall(10.0, visible=0.1) == 1.0
    assert model.sure(0.51)


def test_realistic_is_mask_rcnn_by_size_and_harsh_halves_it_with_twice_the_false() -> None:
    realistic, harsh = preset("realistic"), preset("harsh")
    small, medium, large = MASK_RCNN_RECALL
    assert realistic.recall(SMALL_PX - 1) == small
    assert realistic.recall(SMALL_PX) == medium
    assert realistic.recall(LARGE_PX) == large
    assert realistic.recall(LARGE_PX, visible=0.3) == pytest.approx(large * 0.5)
    assert harsh.recall(LARGE_PX) == pytest.approx(large / 2)
    assert harsh.fp_per_image == 2 * realistic.fp_per_image
    assert not realistic.perfect and not harsh.perfect
    # Each preset's confirmation threshold, as the protocol's rule chose it (0.999 for harsh).
    assert (realistic.accept_posterior, harsh.accept_posterior) == (0.99, 0.999)


def test_a_score_is_evidence_by_its_likelihood_ratio() -> None:
    model = preset("realistic")
    # Beta(2, 1) over Beta(1.5, 4) is 2 B(1.5, 4) √u / (1 - u)³ above the threshold.
    u = (0.8 - model.threshold) / (1 - model.threshold)
    b = math.gamma(1.5) * math.gamma(4) / math.gamma(5.5)
    assert model.likelihood_ratio(0.8) == pytest.approx(2 * b * math.sqrt(u) / (1 - u) ** 3)
    assert model.likelihood_ratio(1.0) == math.inf
    assert model.likelihood_ratio(model.threshold) == 0.0
    assert model.sure(0.97) and not model.sure(0.7)


def test_the_run_spec_round_trips_and_bad_values_are_refused() -> None:
    model = preset("harsh", fp_per_image=1.0)
    assert PerceptionModel.from_params(model.params()) == model
    assert PerceptionModel.from_params(None) == PerceptionModel()
    with pytest.raises(ObjsearchError, match="unknown perception preset"):
        preset("blurry")
    with pytest.raises(ObjsearchError, match="recall_scale must be in"):
        preset("realistic", recall_scale=1.5)
    with pytest.raises(ObjsearchError, match="unknown perception parameter"):
        PerceptionModel.from_params({"recall": 1.0})


def test_the_consistent_confirmation_counts_a_look_against_a_recurring_false_report() -> None:
    # A sequence of confirming looks at a small object (900 px, taken as occluded: r = 0.323 / 2)
    # from prior odds 2: a report at 0.8, a miss, a report at 0.7. The score rule counts a report
    # by its score alone and a miss by 1 - r; the consistent one, with q = 0.3, a report by
    # r / q times its score's ratio and a miss by (1 - r) / (1 - q).
    score, consistent = (
        preset("realistic", "score"),
        preset("realistic", "consistent", fp_recurrence=0.3),
    )
    r = MASK_RCNN_RECALL[0] * 0.5
    looks: list[float | None] = [0.8, None, 0.7]
    by_score = by_consistent = 2.0
    for s in looks:
        by_score *= score.look_ratio(900.0, s)
        by_consistent *= consistent.look_ratio(900.0, s)
    lr8, lr7 = score.likelihood_ratio(0.8), score.likelihood_ratio(0.7)
    assert by_score == pytest.approx(2.0 * lr8 * (1 - r) * lr7)
    assert by_consistent == pytest.approx(2.0 * (r / 0.3) ** 2 * lr8 * lr7 * (1 - r) / 0.7)
    # A score of 1 stays certain; a large object's report is stronger evidence than a small one's.
    assert consistent.look_ratio(900.0, 1.0) == math.inf
    assert consistent.look_ratio(LARGE_PX, 0.8) > consistent.look_ratio(900.0, 0.8)


def test_the_confirmation_is_recorded_only_when_it_is_not_the_committed_rule() -> None:
    # Run specs of the score rule are what they were before the option (golden logs, set A).
    assert "confirmation" not in preset("realistic", "score").params()
    assert "fp_recurrence" not in preset("realistic", "score", fp_recurrence=0.5).params()
    model = preset("harsh", "consistent", fp_recurrence=0.5)
    doc = model.params()
    assert doc["confirmation"] == "consistent" and doc["fp_recurrence"] == 0.5
    assert PerceptionModel.from_params(doc) == model
    with pytest.raises(ObjsearchError, match="unknown confirmation"):
        preset("realistic", "sometimes")


def test_each_preset_confirms_by_its_own_model_and_old_run_specs_stay_score() -> None:
    # realistic confirms by consistent, q = 0.1 (chosen by the protocol's rule on evaluation A);
    # harsh and perfect by score. A run spec without a confirmation (every run before the
    # option) is the score rule, whatever the preset's default is now: replays stay exact.
    assert preset("realistic").confirmation == "consistent"
    assert preset("realistic").fp_recurrence == 0.1
    assert preset("harsh").confirmation == preset("perfect").confirmation == "score"
    doc = preset("realistic").params()
    assert doc["confirmation"] == "consistent" and doc["fp_recurrence"] == 0.1
    old = preset("realistic", "score").params()
    assert PerceptionModel.from_params(old).confirmation == "score"
    with pytest.raises(ObjsearchError, match="fp_recurrence must be in"):
        preset("realistic", "consistent", fp_recurrence=1.0)
