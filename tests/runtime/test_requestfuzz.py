"""The request fuzzer against real ``objsearch agent run`` and ``objsearch robot sim`` processes
over Zenoh on 127.0.0.1: a few hundred broken requests, then a valid search that must give the
in-process simulator's answer. (``benchmarks/request_fuzz.py`` runs thousands.)"""

from __future__ import annotations

from pathlib import Path

import pytest

from devtools.requestfuzz import (
    RECEIVER,
    CaseMaker,
    Rig,
    free_port,
    fuzz_rig,
    simulated,
)
from objsearch.runtime.config import RuntimeConfig

pytest.importorskip("zenoh")


def test_cases_are_seeded_and_cover_every_request_type() -> None:
    def cases(seed: int) -> list[tuple[str, bytes, str]]:
        maker = CaseMaker(RuntimeConfig(), seed)
        return [(c.kind, c.payload, c.expect) for c in maker.cases(400)]

    first = cases(7)
    assert first == cases(7) and first != cases(8)
    assert {kind for kind, _, _ in first} == set(RECEIVER)
    assert {expect for _, _, expect in first} == {"error", "drop"}
    fields = {c.field for c in CaseMaker(RuntimeConfig(), 7).cases(400) if c.kind == "find"}
    assert {"target", "start", "scene", "not_before_ns"} <= fields


def test_agent_survives_the_fuzzer_and_then_searches_correctly(tmp_path: Path) -> None:
    expected = simulated(tmp_path / "inproc")
    assert expected["task_id"] == "task-00001" and expected["success"]
    rig = Rig(tmp_path, free_port())
    rig.start()
    try:
        counts, result = fuzz_rig(rig, 300, seed=12, expected=expected)
    finally:
        rig.stop()
    print(counts.line())
    assert counts.wrong == [], counts.wrong[:10]
    assert counts.crashed == 0, rig.output("agent")[-3000:] + rig.output("robot")[-3000:]
    assert counts.tried == 300 == counts.error_answered + counts.dropped
    assert counts.error_answered > 100 and counts.drops_by["agent"] > 10
    assert counts.drops_by["robot"] > 10
    assert "Traceback" not in rig.output("agent") + rig.output("robot")
    assert counts.served == 1 and result["task_id"] == "task-00001"  # no case started a task
