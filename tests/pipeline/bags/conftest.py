"""Fixtures for the bag tests: one simulated search recorded to each bag format, with its log."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.pipeline.bags.formats import BagFormat

from .bag_fixtures import SHARED_BAGS, Recorded, record_run


@pytest.fixture(scope="session", params=[f.value for f in BagFormat])
def recorded(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    fmt = BagFormat(request.param)
    return record_run(tmp_path_factory.mktemp(f"bag-{fmt.value}"), fmt)


@pytest.fixture(scope="session")
def shared_bags() -> Path:
    if not SHARED_BAGS.is_dir():
        pytest.skip(f"the shared real bags are not at {SHARED_BAGS} (../shared is absent)")
    return SHARED_BAGS
