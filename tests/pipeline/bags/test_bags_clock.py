"""The receive-time → agent-clock map (pipeline/bags/clock.py)."""

from __future__ import annotations

import numpy as np
import pytest

from objsearch.pipeline.bags.clock import MAX_PAIRS, fit_clock, kept_pairs, pairs_from_doc

STAMP0 = 1_767_225_600_000_000_000  # 2026-01-01, the agent's clock
RECV0 = 1_796_169_600_000_000_000  # 2026-12-02, the recorder's


def test_clocks_that_agree_need_no_map() -> None:
    assert fit_clock([]) is None
    assert fit_clock([(5, 5), (9, 9)]) is None


def test_an_offset_and_a_rate_are_recovered() -> None:
    stamps = [STAMP0 + k * 1_500_000_000 for k in range(40)]
    pairs = [(RECV0 + (s - STAMP0) // 20, s) for s in stamps]
    clock = fit_clock(pairs)
    assert clock is not None and clock.rate == pytest.approx(20, rel=1e-9) and clock.rate_fitted
    assert clock.residual_ns <= 20
    assert clock.at(RECV0 + 10**9) == pytest.approx(STAMP0 + 20 * 10**9, abs=40)
    received = np.array([RECV0, RECV0 + 3 * 10**9], dtype=np.int64)
    assert clock.apply(received).tolist() == [clock.at(int(t)) for t in received]


def test_events_at_one_instant_give_an_offset_and_no_rate() -> None:
    clock = fit_clock([(RECV0, STAMP0), (RECV0 + 1000, STAMP0)])
    assert clock is not None and clock.rate == 1.0 and not clock.rate_fitted
    assert "offset alone" in clock.describe()
    assert abs(clock.at(RECV0) - STAMP0) <= 500


def test_kept_pairs_are_few_spread_and_keep_the_ends() -> None:
    pairs = [(RECV0 + k, STAMP0 + 20 * k) for k in range(1000)]
    kept = kept_pairs(reversed(pairs))
    assert len(kept) == MAX_PAIRS and kept[0] == pairs[0] and kept[-1] == pairs[-1]
    assert list(kept) == sorted(kept)


def test_pairs_come_back_from_a_report_as_written_or_as_read() -> None:
    pairs = ((RECV0, STAMP0), (RECV0 + 1, STAMP0 + 20))
    assert pairs_from_doc(pairs) == list(pairs)  # dataclasses.asdict keeps tuples
    assert pairs_from_doc([list(p) for p in pairs]) == list(pairs)  # JSON gives lists
    assert pairs_from_doc(None) == [] and pairs_from_doc([[1, "x"], [2]]) == []
