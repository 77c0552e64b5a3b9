"""bench homes under a modelled detector: each strategy beside the distribution oracle that sees
with the same detector, and path ÷ that reference on the same searches."""

from __future__ import annotations

import json

import pytest

from objsearch.agent.detector_model import preset
from objsearch.experiments.homes import homes_jobs, homes_summary, reference_ratio, render
from objsearch.experiments.runner import Row


def _row(strategy: str, scene: int, path: float, start: str = "s1") -> Row:
    return Row(
        "homes", "ithor-02", "habit-0", strategy, "all", 0, scene, "Cup", start, True, path,
        path / 2, f"t{scene}",
    )  # fmt: skip


def test_a_noisy_bench_runs_the_reference_with_the_same_detector_and_a_perfect_one_not() -> None:
    perception = json.dumps(preset("realistic").params(), sort_keys=True)
    noisy = homes_jobs(
        ["ithor-02"], ["global-belief+cover", "wpl"], 1, schedules=("habit",),
        perception=perception,
    )  # fmt: skip
    names = {j.strategy for j in noisy}
    assert {"dist-oracle-global+cover", "dist-oracle-global"} <= names
    assert all(j.perception == perception for j in noisy)
    perfect = homes_jobs(["ithor-02"], ["global-belief+cover"], 1, schedules=("habit",))
    assert {j.strategy for j in perfect} == {"global-belief+cover"}


def test_path_over_the_reference_pairs_the_same_searches() -> None:
    mine = [_row("global-belief+cover", 1, 12.0), _row("global-belief+cover", 2, 6.0)]
    reference = [
        _row("dist-oracle-global+cover", 1, 10.0),
        _row("dist-oracle-global+cover", 2, 5.0),
        _row("dist-oracle-global+cover", 3, 100.0),  # a search the strategy did not make
    ]
    assert reference_ratio(mine, reference) == pytest.approx(18.0 / 15.0)
    assert reference_ratio(mine, [_row("dist-oracle-global+cover", 1, 1.0, "s2")]) is None
    summary = homes_summary([*mine, *reference])
    overall = summary["overall"]["global-belief+cover"]
    assert overall["reference"] == "dist-oracle-global+cover"
    assert overall["reference_ratio"] == pytest.approx(1.2)
    assert "reference_ratio" not in summary["overall"]["dist-oracle-global+cover"]
    summary.update(homes=["ithor-02"], seeds=[0], perception={"preset": "realistic"})
    text = render(summary)
    assert "÷ ref" in text and "1.20" in text
