"""The lake derives the installed catalogue's tables: the store's own ``searches`` and whatever
tables the domain hands over with its catalogue (none here)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from objsearch.events import install
from objsearch.events.catalogue import installed, schemas_only
from objsearch.events.derived import SEARCHES, derive_run, derived_tables


@pytest.fixture
def bare_catalogue() -> Iterator[None]:
    """The store with a catalogue that hands over no derived tables; the domain's afterwards."""
    before = installed()
    install(schemas_only())
    try:
        yield
    finally:
        install(before)


@pytest.mark.usefixtures("bare_catalogue")
def test_a_catalogue_without_derived_tables_gets_searches_only() -> None:
    assert derived_tables() == (SEARCHES,)
    derived = derive_run({}, robot="r", date="2026-01-01", run="x")
    assert list(derived) == ["searches"]
    assert derived["searches"].num_rows == 0
