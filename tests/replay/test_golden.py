"""Regression from replay: today's code must make every decision the golden logs recorded.

When a change is meant to alter decisions, re-record the goldens with `make bless` and commit them
with the change; the diff of the logs is then part of the review.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.experiments.golden import BAG_LAKE, GOLDEN_RUNS
from objsearch.replay.decisions import replay
from objsearch.replay.source import open_events

GOLDEN_DIR = Path(__file__).resolve().parent / "golden"  # `make bless` writes here
GOLDEN = sorted(p for p in GOLDEN_DIR.iterdir() if p.is_dir() and not p.name.startswith("."))


def test_every_golden_is_committed() -> None:
    assert [p.name for p in GOLDEN] == sorted([BAG_LAKE, *(run.name for run in GOLDEN_RUNS)])


@pytest.mark.parametrize("log", GOLDEN, ids=lambda p: p.name)
def test_todays_code_makes_the_recorded_decisions(log: Path) -> None:
    events, _ = open_events(log)  # a log folder, or the lake holding the ingested bag
    replayer = replay(events)
    assert replayer.decisions, "a golden log without plans tests nothing"
    assert not replayer.notes, replayer.notes
    changed = [d for d in replayer.decisions if not d.same]
    diff = "\n".join(
        f"seq {d.seq} {d.task_id} {d.target} in {d.room}:\n"
        f"  rooms    {list(d.recorded_rooms)}\n        →  {list(d.replayed_rooms)}\n"
        f"  order    {list(d.recorded_order)}\n        →  {list(d.replayed_order)}\n"
        + "".join(f"  because {r}\n" for r in d.reasons)
        for d in changed
    )
    assert not changed, (
        f"{len(changed)} of {len(replayer.decisions)} decisions changed "
        f"(if intended: `make bless`):\n{diff}"
    )
