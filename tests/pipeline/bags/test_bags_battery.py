"""The damaged-bag battery, small: every kind of damage per format, accounted for per topic.

``benchmarks/damaged_bags.py`` runs the same with many more variants and the shared real bags.
"""

from __future__ import annotations

import shutil
from collections import Counter
from pathlib import Path

import pytest

from devtools.bag_battery import Ingested, account, ingest_cli, variants
from objsearch.cli import main

from .bag_fixtures import Recorded

PER_KIND = 3  # variants per kind of damage and format; seeded
SEED = 12


@pytest.fixture(scope="module")
def intact_ingest(recorded: Recorded, tmp_path_factory: pytest.TempPathFactory) -> Ingested:
    lake = tmp_path_factory.mktemp("intact-lake")
    return ingest_cli(recorded.bag, lake, main)


def test_intact_bag_is_complete(recorded: Recorded, intact_ingest: Ingested) -> None:
    assert intact_ingest.code == 0, intact_ingest.stderr
    assert intact_ingest.report is not None
    assert account(intact_ingest, intact_ingest).outcome == "complete"
    rows = {t["topic"]: t for t in intact_ingest.report["topics"]}
    for topic, n in recorded.recording.messages.items():
        assert rows[topic]["messages"] == n
        assert rows[topic]["claimed"] == n
        assert rows[topic]["lost"] == 0
    # /tf's poses are dropped when odometry gives them: the report credits it with none.
    assert rows["/tf"]["events"] == 0
    assert rows["/odom"]["events"] == intact_ingest.lake_rows["/odom"] == rows["/odom"]["messages"]


def test_every_damaged_variant_is_accounted_for(
    recorded: Recorded, intact_ingest: Ingested, tmp_path: Path
) -> None:
    fmt = recorded.recording.format
    outcomes: Counter[str] = Counter()
    problems = []
    for i, v in enumerate(variants(recorded.bag, fmt, SEED, PER_KIND)):
        where = tmp_path / f"v{i}"
        bag = v.make(where / "bag")
        verdict = account(intact_ingest, ingest_cli(bag, where / "lake", main))
        outcomes[f"{v.kind}:{verdict.outcome}"] += 1
        if verdict.outcome not in ("complete", "loss-reported", "error"):
            problems.append(f"{v.name}: {verdict.outcome}: {'; '.join(verdict.problems)}")
        shutil.rmtree(where)
    assert not problems, "\n".join(problems)
    # The battery can fail: damage that loses messages is reported as such.
    assert outcomes["zero:loss-reported"] >= 1, outcomes
    assert sum(n for k, n in outcomes.items() if k.startswith("cut:") and "loss" in k) >= 1
