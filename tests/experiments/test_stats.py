"""Spreads over runs: an interval only over enough runs, else n and the range."""

from __future__ import annotations

import pytest

from objsearch.experiments.stats import CI, MIN_RUNS, RANGE, bootstrap_mean, method_note, spread


def test_few_runs_give_n_and_the_range_not_an_interval() -> None:
    # Two runs: a percentile bootstrap's "95 % CI" would be exactly the two values.
    s = spread([1.0, 3.0])
    assert (s.n, s.mean, s.low, s.high, s.kind) == (2, 2.0, 1.0, 3.0, RANGE)
    assert not s.is_interval
    assert s.text() == f"range [+1.00, +3.00], n = 2 (no CI: < {MIN_RUNS} runs)"


def test_enough_runs_give_a_seeded_bootstrap_interval_inside_the_range() -> None:
    values = [float(i) for i in range(MIN_RUNS)]
    s = spread(values)
    assert s.kind == CI and s.is_interval
    assert min(values) < s.low < s.mean < s.high < max(values)
    assert s.text() == f"[{s.low:+.2f}, {s.high:+.2f}]"
    assert spread(values) == s  # seeded
    # The interval narrows as runs agree more.
    tight = spread([4.5 + 0.01 * v for v in values])
    assert tight.high - tight.low < (s.high - s.low) / 50


def test_bootstrap_of_a_constant_is_the_constant() -> None:
    assert bootstrap_mean([2.5] * 12, resamples=100) == pytest.approx((2.5, 2.5))


def test_no_runs_is_an_error_and_the_note_states_the_rule() -> None:
    with pytest.raises(ValueError):
        spread([])
    assert f"at least {MIN_RUNS} runs" in method_note() and "10 000 resamples" in method_note()
