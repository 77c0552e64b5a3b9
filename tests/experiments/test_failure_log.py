"""Why a search failed, read from its run's log (experiments/failure_log.py), on real runs of a
modelled detector made to fail."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from objsearch.agent.detector_model import preset
from objsearch.experiments.runner import Job, Row, read_rows, run_job, write_rows


def _search(target: str, **detector: float) -> list[str | None]:
    # Draws by view, reports as misses, no relook, pooled stop misses: the scenarios below were
    # found under them (each names its search).
    perception = json.dumps(
        preset("realistic", "score", "view", "misses", "off", "pooled", **detector).params(),
        sort_keys=True,
    )
    job = Job(
        "homes", "ithor-02", "habit-0", "global-belief", "all", 0, targets=(target,),
        scenes=(1,), starts_per_search=1, perception=perception,
    )  # fmt: skip
    rows = run_job(job)
    assert rows and not any(r.success for r in rows)
    assert all((r.failure is not None) for r in rows)
    return [r.failure for r in rows]


def test_a_confusion_confirmed_is_named_with_the_class_it_was() -> None:
    """ithor-02 habit-0 scene 1: every detection confused, a sighting confirmed at P ≥ 0.5: the
    Cup search ends on the Bowl reported as a Cup."""
    (cause,) = _search("Cup", confusion=1.0, fp_per_image=0.0, accept_posterior=0.5)
    assert cause is not None
    assert cause.startswith("false found: a Bowl reported as Cup at score ")
    assert cause.endswith("(a confusion) confirmed")


def test_a_target_never_reported_says_so_with_the_stopping_rule() -> None:
    (cause,) = _search("Cup", recall_scale=0.0, fp_per_image=0.0)
    assert cause is not None
    assert cause.startswith("not found (Cup not found: budget of 8 passes spent")
    assert cause.endswith("the true target was never reported")


def test_a_target_reported_only_under_its_mask_threshold_says_how_large_it_was() -> None:
    """procthor-01 habit-3 scene 10, perfect detector: the Phone on the living room's shelf shows
    at most 65 px (< 100 px, its class's threshold) from the views the search takes, so it is
    reported but never a sighting; the cause gives the largest mask."""
    job = Job(
        "homes", "procthor-01", "habit-3", "dist-oracle-global+cover", "all", 3,
        targets=("Phone",), scenes=(10,), starts_per_search=1,
    )  # fmt: skip
    (row,) = run_job(job)
    assert not row.success and row.failure is not None
    assert row.failure.startswith("not found (Phone not found in any room): the true target was")
    assert row.failure.endswith("largest mask 65 px)")


def test_a_successful_search_has_no_cause_and_every_place_forecast() -> None:
    rows = run_job(
        Job("homes", "ithor-02", "habit-0", "global-belief", "all", 0, targets=("Cup",),
            scenes=(1, 2), starts_per_search=1)
    )  # fmt: skip
    assert [r.success for r in rows] == [True, True]
    for r in rows:
        assert r.failure is None
        assert r.belief_others is not None and r.belief_p_found is not None
        others = [float(p) for p in r.belief_others.split()]
        # Every place of the forecast: the found one and the others sum to the whole belief.
        assert len(others) > 10
        assert abs(r.belief_p_found + sum(others) - 1.0) < 1e-3


def test_a_cause_after_the_first_hundred_rows_is_written_and_read_back(tmp_path: Path) -> None:
    """polars typed the column from the first 100 rows: all None there (every search succeeded)
    made it null, and the first cause after them failed the whole bench homes run."""
    ok = Row("homes", "ithor-02", "habit-0", "wpl", "all", 0, 1, "Cup", "s", True, 1.0, 1.0, "t")
    rows = [replace(ok, task_id=f"t{i:03d}") for i in range(150)]
    rows.append(replace(ok, task_id="t150", success=False, failure="not found (budget spent)"))
    parquet, _ = write_rows(rows, tmp_path, "homes_trials")
    assert read_rows(parquet)[-1].failure == "not found (budget spent)"
