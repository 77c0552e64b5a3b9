"""The live view's WebSocket battery (``devtools.wsflood``) at test size: hostile
connections of every kind against a live view drawing a real log; nothing is lost, nothing
changes silently, nothing crashes. (``benchmarks/ws_flood.py`` runs thousands.)"""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import read_log
from objsearch.runtime.standin import in_process_search


def test_hostile_clients_get_clear_errors_and_the_viewer_loses_nothing(tmp_path: Path) -> None:
    pytest.importorskip("foxglove")
    from devtools.wsflood import KINDS, report, run_battery

    in_process_search(tmp_path / "log", 1, "Apple", "kitchen-1")
    counts = run_battery(list(read_log(tmp_path / "log", store=STORE)), 120, seed=3)
    print("\n".join(report(counts)))
    assert (counts.traceback, counts.silent_change, counts.loss) == (0, 0, 0), counts.problems
    assert counts.tried == 120 == counts.clear_error + counts.unchanged
    assert set(counts.by_kind) == set(KINDS)
    assert counts.peak_connections <= 8
    server = counts.server
    assert server is not None
    assert server.evicted + server.timed_out > 0 and server.dropped_slow > 0
    assert counts.probe_messages > 100
