"""The lake derives its store's tables: the store's own ``searches`` and whatever tables the
domain hands over with its catalogue (none here)."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import EventStoreError
from objsearch.events.derived import SEARCHES, derive_run, derived_tables
from objsearch.events.store import shipped


def test_a_catalogue_without_derived_tables_gets_searches_only() -> None:
    assert derived_tables(shipped()) == (SEARCHES,)
    derived = derive_run({}, robot="r", date="2026-01-01", run="x", store=shipped())
    assert list(derived) == ["searches"]
    assert derived["searches"].num_rows == 0


def test_two_stores_live_side_by_side() -> None:
    """Nothing is installed process-wide: the bare store and the product's coexist."""
    assert derived_tables(shipped()) == (SEARCHES,)
    assert len(derived_tables(STORE)) > 1
    assert derived_tables(shipped()) == (SEARCHES,)


def test_a_store_without_upcasters_refuses_an_old_version_by_name(tmp_path: Path) -> None:
    """The bare store reads latest versions; an old one is an error naming the missing step."""
    with pytest.raises(EventStoreError, match=r"no upcaster for run_started v1 → v2.*STORE"):
        shipped().upcaster.upcast_payload("run_started", 1, {})
    assert STORE.upcaster.latest_version("run_started") == shipped().registry.latest_version(
        "run_started"
    )
