"""A closed container is never looked at from outside: every view the log attributes to a
container is the look inside it once opened, so the belief, which counts each view of a place as a
miss there (agent/belief.py), never counts a look at the closed door as a miss inside (the README
says so of its first example; issue 47 asked)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, NamedTuple

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.session import load_context
from objsearch.cli import main
from objsearch.events import read_log
from objsearch.events.projection import EventView

TARGETS = ("Apple", "Bowl", "Cup", "Laptop", "Phone", "Pillow", "ToiletPaper", "Vase")


def outside_looks(events: Iterable[EventView], containers: set[str]) -> list[int]:
    """The seqs of views attributed to a container that are not the look inside it, right after
    it was opened at the same pose."""
    bad: list[int] = []
    opened: dict[str, object] = {}
    for e in events:
        if e.type == "container_opened":
            opened[e.payload["static_id"]] = e.payload["pose"]
        elif e.type == "view_taken" and e.payload["static_id"] in containers:
            static = e.payload["static_id"]
            if e.payload["reason"] != "inside" or opened.pop(static, None) != e.payload["pose"]:
                bad.append(e.seq)
    return bad


def _events(log: Path) -> list[EventView]:
    return list(read_log(log, store=STORE))


@pytest.mark.parametrize("strategy", ["global-belief+cover", "wpl"])
def test_a_closed_container_is_never_looked_at_from_outside(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], strategy: str
) -> None:
    containers = {s.id for s in load_context("paper").semmap.statics if s.container}
    assert {c.split("|")[0] for c in containers} >= {"kitchen/Fridge", "kitchen/Microwave"}
    inside = 0
    for target in TARGETS:
        log = tmp_path / target
        args = ["search", target, "--start", "kitchen-1", "--strategy", strategy]
        assert main([*args, "--log", str(log), "--format", "json"]) in (0, 1)
        capsys.readouterr()
        events = _events(log)
        assert outside_looks(events, containers) == [], target
        inside += sum(e.type == "container_opened" for e in events)
    assert inside >= len(TARGETS)  # the check met containers: each search opened one at least


class _View(NamedTuple):
    seq: int
    type: str
    task_id: str | None
    payload: Mapping[str, Any]


def test_the_check_finds_a_look_at_a_closed_container(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "log"
    assert main(["search", "Apple", "--start", "kitchen-1", "--log", str(log)]) == 0
    capsys.readouterr()
    events = [_View(e.seq, e.type, e.task_id, e.payload) for e in _events(log)]
    opened = next(
        e for e in events if e.type == "container_opened" and "/Fridge|" in e.payload["static_id"]
    )
    fridge = opened.payload["static_id"]
    assert outside_looks(events, {fridge}) == []
    # The same log with a counter top's look attributed to the closed fridge instead.
    look = next(e for e in events if e.type == "view_taken" and e.payload["reason"] == "look")
    forged = [
        e._replace(payload={**e.payload, "static_id": fridge}) if e is look else e for e in events
    ]
    assert outside_looks(forged, {fridge}) == [look.seq]
    # The look inside taken at another pose than the opening's.
    pose = {**opened.payload["pose"], "x": -1.0}
    forged = [e._replace(payload={**e.payload, "pose": pose}) if e is opened else e for e in events]
    assert len(outside_looks(forged, {fridge})) == 1
