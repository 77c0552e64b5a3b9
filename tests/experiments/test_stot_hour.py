"""The hour-of-day histogram of ``routine-hour`` (objsearch.experiments.stot_hour)."""

from __future__ import annotations

import pytest

from objsearch.experiments.stot_hour import HourHistogram, hour_of

DAY = 1440


def test_the_hour_is_the_hour_of_the_day_of_its_minutes() -> None:
    assert hour_of(0) == 0
    assert hour_of(9 * 60 + 59) == 9
    assert hour_of(10 * 60) == 10
    assert hour_of(3 * DAY + 23 * 60 + 50) == 23
    assert hour_of(5 * DAY) == 0


def test_each_parent_has_its_share_of_the_observed_steps_in_that_hour() -> None:
    hours = HourHistogram()
    # Three days; at 09:00 and 09:30 the mug is on the table twice and on the desk four times,
    # at 10:00 always on the shelf; the cup is seen at 09:00 on day 0 only.
    for day in range(3):
        base = day * DAY
        hours.observe(base + 9 * 60, {"mug": "table" if day == 0 else "desk", "cup": "sink"})
        hours.observe(base + 9 * 60 + 30, {"mug": "table" if day == 1 else "desk"})
        hours.observe(base + 10 * 60, {"mug": "shelf"})
    # Any minute of the hour, any later day: 2 of 6 steps on the table, 4 on the desk.
    later = 7 * DAY + 9 * 60 + 50
    assert hours.forecast("mug", later) == pytest.approx({"table": 2 / 6, "desk": 4 / 6})
    assert hours.forecast("mug", 7 * DAY + 10 * 60 + 10) == {"shelf": 1.0}
    assert hours.forecast("cup", later) == {"sink": 1.0}
    # No prior, no decay: one more step moves the share by exactly one count.
    hours.observe(8 * DAY + 9 * 60, {"mug": "table"})
    assert hours.forecast("mug", later) == pytest.approx({"table": 3 / 7, "desk": 4 / 7})


def test_an_hour_never_observed_forecasts_the_last_parent_seen() -> None:
    hours = HourHistogram()
    assert hours.forecast("mug", 9 * 60) == {}
    hours.observe(9 * 60, {"mug": "table"})
    hours.observe(10 * 60, {"mug": "desk"})
    hours.observe(DAY + 9 * 60, {"mug": "sofa"})
    # 15:00 was never observed: where the mug was last seen (the sofa), not the hours' mix.
    assert hours.forecast("mug", DAY + 15 * 60) == {"sofa": 1.0}
    assert hours.forecast("cup", DAY + 9 * 60) == {}
