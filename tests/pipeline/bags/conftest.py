"""Fixtures for the bag tests: one simulated search recorded to each bag format, with its log,
and the ROS 1 recording cut into pieces of a minute."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.pipeline.bags.formats import BagFormat

from .bag_fixtures import SHARED_BAGS, Recorded, record_run
from .splitter import split_ros1


@pytest.fixture(scope="session", params=[f.value for f in BagFormat])
def recorded(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    fmt = BagFormat(request.param)
    if fmt is BagFormat.ROS1:
        ros1: Recorded = request.getfixturevalue("ros1")  # the same recording, made once
        return ros1
    return record_run(tmp_path_factory.mktemp(f"bag-{fmt.value}"), fmt)


@pytest.fixture(scope="session")
def ros1(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    """The search recorded to ROS 1 (one recording for every module that reads it)."""
    return record_run(tmp_path_factory.mktemp("bag-ros1"), BagFormat.ROS1)


@pytest.fixture(scope="session")
def pieces(ros1: Recorded, tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """:func:`ros1` cut into pieces of a minute of recording each."""
    cut = split_ros1(ros1.bag, tmp_path_factory.mktemp("split"), duration_s=60.0)
    assert len(cut) >= 3
    return cut


@pytest.fixture(scope="session")
def shared_bags() -> Path:
    if not SHARED_BAGS.is_dir():
        pytest.skip(f"the shared real bags are not at {SHARED_BAGS} (../shared is absent)")
    return SHARED_BAGS
