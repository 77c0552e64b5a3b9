"""``bench table1``: eligibility of FloorPlan sets, the seeded sample, and a run on 2 sets."""

from __future__ import annotations

import json
import os
from pathlib import Path

import polars as pl
import pytest

from objsearch.agent.datapaths import DATA_ENV
from objsearch.cli import main
from objsearch.experiments.table1_sets import (
    Eligibility,
    eligibility,
    ordering,
    paper_order_holds,
    sample_order,
    set_name,
)
from objsearch.pipeline.build import PAPER_HOME
from objsearch.pipeline.home import build_home
from objsearch.pipeline.scenario import table1

from .env_writes import env_writes


@pytest.fixture(scope="module")
def elig(shared_data: Path) -> Eligibility:
    return eligibility(shared_data)


def test_eligibility_counts_every_set_once(elig: Eligibility) -> None:
    assert elig.candidates == 25**4
    assert elig.fail_rule + elig.split_room + len(elig.eligible) == elig.candidates
    assert PAPER_HOME in elig.eligible
    assert "FloorPlan408" in elig.split_rooms  # issue 14: its viewpoints fall into two pieces
    assert not any("FloorPlan408" in s for s in elig.eligible)


def test_per_room_rule_agrees_with_the_build(shared_data: Path, elig: Eligibility) -> None:
    order = sample_order(elig.eligible, 1)
    for scenes in order[:2]:
        table1(build_home(shared_data, set_name(scenes), scenes))  # raises if the rule fails
    eligible = set(elig.eligible)
    failing = next(
        s
        for s in (
            ("FloorPlan1", f"FloorPlan{200 + k}", "FloorPlan301", "FloorPlan401")
            for k in range(1, 26)
        )
        if s not in eligible and "FloorPlan408" not in s
    )
    with pytest.raises(Exception, match="exactly one"):
        table1(build_home(shared_data, set_name(failing), failing))


def test_sample_is_seeded_and_nested(elig: Eligibility) -> None:
    a, b = sample_order(elig.eligible, 1), sample_order(elig.eligible, 1)
    assert a == b and sorted(a) == sorted(elig.eligible)
    assert sample_order(elig.eligible, 2)[:10] != a[:10]


def test_orderings() -> None:
    assert ordering({"sdp": 3.0, "rvp": 2.0, "wpl": 1.0}) == "wpl<rvp<sdp"
    assert ordering({"sdp": 3.0, "rvp": 1.0, "wpl": 1.0}) == "rvp=wpl<sdp"
    assert paper_order_holds({"sdp": 3.0, "rvp": 1.0, "wpl": 1.0})
    assert not paper_order_holds({"sdp": 1.0, "rvp": 2.0, "wpl": 1.0})


def test_bench_table1_on_two_sets(
    shared_data: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The searches read the homes (and all else) of the run's own build, ``OUT/data``, handed
    down to them: no environment variable is set or unset while it runs (issue 47), and one
    naming a folder that holds nothing is not read (a reader left on $OBJSEARCH_DATA fails)."""
    out = tmp_path / "t1"
    nothing = tmp_path / "no-data"
    nothing.mkdir()
    monkeypatch.setenv(DATA_ENV, str(nothing))
    before = dict(os.environ)
    argv = ["bench", "table1", "--sets", "2", "--seed", "1", "--out", str(out)]
    argv += [
        "--source",
        str(shared_data),
        "--targets",
        "Cup,Vase",
        "--workers",
        "1",
        "--no-progress",
    ]
    argv += ["--prior", "vg-hoz-masked"]
    with env_writes() as writes:
        code = main(argv)
    assert code == 0
    assert writes == []
    assert dict(os.environ) == before
    printed = capsys.readouterr().out
    assert "WPL ≤ RVP < SDP" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert summary["summary"]["sets"] == 2
    assert summary["prior"] == "vg-hoz-masked" and "--prior vg-hoz-masked" in summary["command"]
    assert len(summary["sample"]) == 2
    sets = pl.read_csv(out / "table1_sets.csv")
    # the two sampled sets and the paper's set (unless sampled)
    assert sets.height == 2 + (set_name(PAPER_HOME) not in summary["sample"])
    trials = pl.read_csv(out / "table1_trials.csv")
    # per home: (2 SDP seeds + RVP + WPL) × 2 targets × 8 starts
    assert trials.height == sets.height * 4 * 2 * 8
    to_discovery = pl.col("path_to_discovery").fill_null(pl.col("path_length"))
    assert trials.select((to_discovery <= pl.col("path_length") + 1e-9).all()).item()
    for name in ("sdp", "rvp", "wpl"):
        d = summary["summary"]["distribution"][name]
        assert 0 < d["p5"] <= d["median"] <= d["p95"]
    assert (out / "data" / "homes" / f"{summary['sample'][0]}.json").is_file()
    assert "| SDP |" in (out / "summary.md").read_text()
