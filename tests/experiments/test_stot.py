"""The SpatioTemporalObjectTracking harness (objsearch.experiments.stot).

Its code and data are not part of objsearch: the test that runs its evaluation needs a checkout
of the pinned commit in ``$OBJSEARCH_STOT_SOURCE`` and is skipped without one. The pinning, our
method at its seam on a tiny synthetic household, the scoring and the CLI's errors are tested
everywhere.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest
import torch

from devtools.cli_process import run_cli
from objsearch.agent.errors import ObjsearchError
from objsearch.experiments import stot

#: A tiny household: two pieces of furniture and a room (static), a mug that is on the table in
#: the morning and on the desk in the evening, every day.
NODES = ["kitchen", "table", "desk", "mug"]
MUG, TABLE, DESK, KITCHEN = 3, 1, 2, 0
MASK = [[0.0] * 4, [0.0] * 4, [0.0] * 4, [1.0, 1.0, 1.0, 0.0]]
DAY = 1440


def _graph(mug_at: int) -> torch.Tensor:
    edges = torch.zeros((4, 4))
    edges[TABLE, KITCHEN] = edges[DESK, KITCHEN] = 1.0
    edges[MUG, mug_at] = 1.0
    return edges


def _mug_at(minute: int) -> int:
    return TABLE if minute % DAY < 17 * 60 else DESK


def _trained(model: str, days: int = 14) -> stot.BeliefMethod:
    method = stot.BeliefMethod(model, NODES, MASK, dt=60)
    for day in range(days):
        for hour in range(6, 24):
            minute = day * DAY + hour * 60
            method.observe_graph(minute, _graph(_mug_at(minute)))
    return method


def _batch(edges: torch.Tensor, minute: int, gt: int) -> dict[str, torch.Tensor]:
    return {
        "edges": edges.unsqueeze(0),
        "nodes": torch.eye(4).unsqueeze(0),
        "y_edges": _graph(gt).unsqueeze(0),
        "dynamic_edges_mask": torch.tensor(MASK).unsqueeze(0),
        "time": torch.tensor([minute]),
    }


def test_the_belief_that_knows_the_hour_forecasts_the_evening_move() -> None:
    ours = _trained("routine-belief")
    morning, evening = 14 * DAY + 9 * 60, 14 * DAY + 19 * 60
    at_morning = ours.forecast("3:mug", morning)
    at_evening = ours.forecast("3:mug", evening)
    assert max(at_morning, key=at_morning.__getitem__) == str(TABLE)
    assert max(at_evening, key=at_evening.__getitem__) == str(DESK)


def test_the_time_blind_belief_has_one_forecast_for_every_hour() -> None:
    ours = _trained("belief")
    assert ours.forecast("3:mug", 14 * DAY + 9 * 60) == ours.forecast("3:mug", 14 * DAY + 19 * 60)


def test_a_step_folds_its_real_input_once_and_not_its_own_fed_back_output() -> None:
    ours = _trained("routine-belief")
    before = ours.episodes
    t = 14 * DAY + 17 * 60  # the input is the graph at 16:00 (mug on the table)
    _, details, _ = ours.step(_batch(_graph(TABLE), t, gt=DESK))
    assert ours.episodes == before + 1
    assert int(details["output"]["location"][0, MUG]) == DESK
    assert int(details["input"]["location"][0, MUG]) == TABLE
    probs = details["output_probs"]["location"]
    assert torch.allclose(probs[0, MUG].sum(), torch.tensor(1.0), atol=1e-5)
    assert float(probs[0, MUG, MUG]) == 0.0  # never its own parent (the mask)
    # Its loop feeds our output back as the next lookahead step's input: not an observation.
    fed = _batch(probs[0], t + 60, gt=DESK)
    fed["edges"] = probs
    ours.step(fed)
    assert ours.episodes == before + 1
    # The next step's real input is.
    ours.step(_batch(_graph(DESK), t + 60, gt=DESK))
    assert ours.episodes == before + 2


def _changed_mornings(model: str) -> stot.BeliefMethod:
    """Fourteen days of the routine, then three days the mug stays on the desk all day."""
    method = _trained(model)
    for day in range(14, 17):
        for hour in range(6, 24):
            method.observe_graph(day * DAY + hour * 60, _graph(DESK))
    return method


def _top(dist: dict[str, float]) -> str:
    return max(dist, key=dist.__getitem__)


def test_beyond_the_next_step_routine_habit_forecasts_the_hours_habit() -> None:
    memory, habit = _changed_mornings("routine-belief"), _changed_mornings("routine-habit")
    seen = 17 * DAY + 8 * 60
    for method in (memory, habit):
        method.observe_graph(seen, _graph(DESK))
    # The next step (one dt after the look): both forecast as the belief does, from the look.
    assert habit.forecast("3:mug", seen + 60) == memory.forecast("3:mug", seen + 60)
    assert _top(memory.forecast("3:mug", seen + 60)) == str(DESK)
    # Two steps on the belief still says the desk; the mornings' habit is the table.
    assert _top(memory.forecast("3:mug", seen + 120)) == str(DESK)
    assert _top(habit.forecast("3:mug", seen + 120)) == str(TABLE)
    # Its lookahead loop: the fed-back step two after the look predicts the move to the table.
    t = seen + 60
    _, first, _ = habit.step(_batch(_graph(DESK), t, gt=DESK))
    assert int(first["output"]["location"][0, MUG]) == DESK
    fed = _batch(first["output_probs"]["location"][0], t + 60, gt=DESK)
    fed["edges"] = first["output_probs"]["location"]
    _, second, _ = habit.step(fed)
    assert int(second["output"]["location"][0, MUG]) == TABLE


def test_a_copy_for_the_other_forecast_folds_alike_and_on_its_own() -> None:
    fresh = _changed_mornings("routine-habit")
    copied = _changed_mornings("routine-belief").as_model("routine-habit")
    for minute in (17 * DAY + 9 * 60, 17 * DAY + 19 * 60):
        fresh.observe_graph(minute, _graph(TABLE))
        copied.observe_graph(minute, _graph(TABLE))
        for later in (minute + 60, minute + 180):
            assert copied.forecast("3:mug", later) == fresh.forecast("3:mug", later)
    original = _trained("routine-belief")
    twin = original.as_model("routine-habit")
    before = twin.forecast("3:mug", 14 * DAY + 9 * 60)
    for day in range(14, 20):
        original.observe_graph(day * DAY + 9 * 60, _graph(DESK))
    assert twin.forecast("3:mug", 14 * DAY + 9 * 60) == before
    with pytest.raises(ValueError, match="folds a different belief"):
        original.as_model("belief")


def test_an_unknown_model_is_refused() -> None:
    with pytest.raises(ValueError, match="routine-belief"):
        stot.BeliefMethod("wpl", NODES, MASK, dt=60)


def _day(method: str, day: str, correct: int, wrong: int, missed: int, fp: int) -> stot.DayResult:
    counts = stot.Counts(correct, wrong, missed, fp, 100)
    return stot.DayResult(3, day, method, [counts] * stot.LOOKAHEAD)


def test_scores_are_its_counts_as_shares_of_the_moved_objects() -> None:
    s = stot.scores(stot.Counts(correct=3, wrong=1, missed=6, fp=2, tn=50))
    assert s["correct"] == pytest.approx(0.3)
    assert s["wrong"] == pytest.approx(0.1)
    assert s["missed"] == pytest.approx(0.6)
    assert s["precision"] == pytest.approx(0.5)
    assert s["f1"] == pytest.approx(2 * 0.5 * 0.3 / 0.8)
    assert math.isnan(stot.scores(stot.Counts(0, 0, 0, 0, 9))["f1"])


def test_the_paired_interval_is_over_days_and_excludes_zero_only_when_every_day_agrees() -> None:
    results = [
        _day("routine-belief", "000.pt", 4, 1, 5, 1),
        _day("routine-belief", "001.pt", 6, 1, 3, 1),
        _day("LastSeen", "000.pt", 0, 0, 10, 0),
        _day("LastSeen", "001.pt", 0, 0, 10, 0),
    ]
    diff, lo, hi, days = stot.paired_ci(results, "routine-belief", "LastSeen", 11, "correct")
    assert days == 2 and diff == pytest.approx(0.5)
    assert 0.4 - 1e-9 <= lo <= diff <= hi <= 0.6 + 1e-9
    same = stot.paired_ci(results, "LastSeen", "LastSeen", 11, "correct")
    assert same[:3] == (0.0, 0.0, 0.0)


def test_a_checkout_that_differs_from_the_pinned_commit_is_refused(tmp_path: Path) -> None:
    (tmp_path / "helpers").mkdir()
    (tmp_path / "helpers" / "reader.py").write_text("# not theirs\n")
    with pytest.raises(ObjsearchError, match=r"is not f4ce4141d3210ba2c18879c64450db6906e534ff"):
        stot.verify_source(tmp_path, "householdsDifferent", [3])
    try:
        stot.verify_source(tmp_path, "householdsDifferent", [3])
    except ObjsearchError as error:
        assert "differs: helpers/reader.py" in str(error)
        assert "missing baselines/baselines.py" in str(error)


def test_without_a_checkout_the_error_says_where_to_put_it(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.delenv(stot.SOURCE_ENV, raising=False)
    with pytest.raises(ObjsearchError, match=r"--source DIR or set \$OBJSEARCH_STOT_SOURCE"):
        stot.verify_source(None, "householdsDifferent", [3])
    with pytest.raises(ObjsearchError, match="no such folder"):
        stot.verify_source(tmp_path / "absent", "householdsDifferent", [3])


def test_its_masks_stay_bool_tensors_and_other_arrays_stay_numpys() -> None:
    # With torch 2.x numpy's bitwise_and of two bool tensors is a uint8 tensor, which its figure
    # code's ``img[mask] *= -0.5`` refuses (RuntimeError).
    np = stot._bool_mask_numpy()
    a, b = torch.tensor([True, False, True]), torch.tensor([True, True, False])
    both = np.bitwise_and(a, b)
    assert both.dtype == torch.bool and both.tolist() == [True, False, False]
    assert np.bitwise_or(a, b).tolist() == [True, True, True]
    assert np.bitwise_not(a).tolist() == [False, True, False]
    img = torch.ones(3)
    img[np.bitwise_and(a, b)] *= -0.5
    assert img.tolist() == [-0.5, 1.0, 1.0]
    assert np.bitwise_and(3, 5) == 1 and np.arange(2).tolist() == [0, 1]


def test_the_blob_id_is_gits() -> None:
    assert stot.git_blob_id(b"") == "e69de29bb2d1d6434b8b29ae775ad8c2e48c5391"
    assert stot.git_blob_id(b"hello\n") == "ce013625030ba8dba906f756967f9e9ca394464a"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--households", "5"], "--households"),
        (["--methods", "LastSeen,Oracle"], "--methods"),
        (["--days", "0"], "--days"),
        (["--dataset", "householdsSame"], "--dataset"),
    ],
)
def test_the_cli_validates_its_options(argv: list[str], message: str, tmp_path: Path) -> None:
    done = run_cli("bench", "stot", "--source", str(tmp_path), *argv)
    assert done.returncode == 2
    assert "objsearch: error:" in done.stderr and message in done.stderr
    assert "Traceback" not in done.stderr


def test_the_cli_refuses_an_unpinned_checkout_with_a_clear_error(tmp_path: Path) -> None:
    done = run_cli("bench", "stot", "--source", str(tmp_path))
    assert done.returncode == 2
    assert "objsearch: error:" in done.stderr and "Traceback" not in done.stderr
    assert "missing baselines/baselines.py" in done.stderr


SOURCE = os.environ.get(stot.SOURCE_ENV, "")


@pytest.mark.slow
@pytest.mark.skipif(
    not SOURCE, reason=f"needs a checkout of the pinned commit in ${stot.SOURCE_ENV}"
)
def test_its_evaluation_scores_lastseen_with_no_move_and_ours_with_some() -> None:
    checkout = stot.verify_source(SOURCE, "householdsDifferent", [4])
    results = stot.run_household(
        checkout, "householdsDifferent", 4, ["routine-belief", "LastSeen"], max_test_days=1
    )
    last = stot.total(results, "LastSeen", stot.LOOKAHEAD - 1)
    ours = stot.total(results, "routine-belief", stot.LOOKAHEAD - 1)
    # LastSeen never predicts a move: every move is missed, nothing is a false positive.
    assert last.correct == last.wrong == last.fp == 0 and last.missed > 0
    # The same day's moves for both (its ground truth does not depend on the method).
    assert ours.moved == last.moved
    assert ours.correct + ours.wrong + ours.fp > 0


def test_the_summary_pairs_routine_habit_with_routine_belief_too() -> None:
    results = [
        _day("routine-habit", "000.pt", 5, 1, 4, 2),
        _day("routine-belief", "000.pt", 2, 0, 8, 1),
        _day("Fremen", "000.pt", 3, 2, 5, 9),
    ]
    paired = stot.summary(results, [])["paired"]
    assert paired["routine-habit - routine-belief correct @12"]["diff"] == pytest.approx(0.3)
    assert "routine-habit - Fremen f1 @12" in paired
    assert "routine-belief - routine-habit f1 @12" not in paired


def test_beyond_the_next_step_routine_hour_forecasts_the_hours_share_of_parents() -> None:
    memory, hour = _changed_mornings("routine-belief"), _changed_mornings("routine-hour")
    seen = 17 * DAY + 8 * 60
    for method in (memory, hour):
        method.observe_graph(seen, _graph(DESK))
    # The next step: as the belief forecasts it, from the look.
    assert hour.forecast("3:mug", seen + 60) == memory.forecast("3:mug", seen + 60)
    # Two steps on: 10:00's observed steps, 14 days on the table and 3 on the desk.
    assert hour.forecast("3:mug", seen + 120) == pytest.approx(
        {str(TABLE): 14 / 17, str(DESK): 3 / 17}
    )
    # 19:00: on the desk all 17 days.
    assert hour.forecast("3:mug", seen + 11 * 60) == {str(DESK): 1.0}
    # Its lookahead loop: the fed-back step two after the look predicts the move to the table.
    t = seen + 60
    _, first, _ = hour.step(_batch(_graph(DESK), t, gt=DESK))
    assert int(first["output"]["location"][0, MUG]) == DESK
    fed = _batch(first["output_probs"]["location"][0], t + 60, gt=DESK)
    fed["edges"] = first["output_probs"]["location"]
    _, second, _ = hour.step(fed)
    assert int(second["output"]["location"][0, MUG]) == TABLE


def test_routine_hour_tells_the_hours_of_one_slot_apart() -> None:
    # Every morning the mug is on the table until 10:00 and on the desk from 10:00 (one slot).
    method = stot.BeliefMethod("routine-hour", NODES, MASK, dt=60)
    for day in range(14):
        for hour in range(6, 24):
            at = TABLE if hour < 10 else DESK
            method.observe_graph(day * DAY + hour * 60, _graph(at))
    seen = 14 * DAY + 6 * 60
    method.observe_graph(seen, _graph(TABLE))
    assert _top(method.forecast("3:mug", seen + 2 * 60)) == str(TABLE)  # 08:00
    assert _top(method.forecast("3:mug", seen + 5 * 60)) == str(DESK)  # 11:00, the same slot
    # A copy for another forecast keeps the same histogram.
    habit = method.as_model("routine-habit")
    assert habit.hours.counts == method.hours.counts
    assert method.as_model("routine-belief").as_model("routine-hour").forecast(
        "3:mug", seen + 5 * 60
    ) == method.forecast("3:mug", seen + 5 * 60)


def test_the_summary_pairs_routine_hour_with_routine_habit() -> None:
    results = [
        _day("routine-hour", "000.pt", 6, 1, 3, 2),
        _day("routine-habit", "000.pt", 5, 1, 4, 2),
        _day("Fremen", "000.pt", 3, 2, 5, 9),
    ]
    paired = stot.summary(results, [])["paired"]
    assert paired["routine-hour - routine-habit correct @12"]["diff"] == pytest.approx(0.1)
    assert "routine-hour - Fremen f1 @12" in paired


def test_the_cli_accepts_routine_hour_among_the_methods(tmp_path: Path) -> None:
    done = run_cli("bench", "stot", "--source", str(tmp_path), "--methods", "routine-hour,Fremen")
    assert done.returncode == 2
    assert "--methods" not in done.stderr  # past the options, to the checkout's check
    assert "missing baselines/baselines.py" in done.stderr
