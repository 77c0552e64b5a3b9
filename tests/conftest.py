"""Fixtures every test package may use: the raw shared data (``../shared/data`` beside the clone,
or ``$OBJSEARCH_SHARED``), which the data converter and the FloorPlan-set benches build homes from."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]


def _shared_data() -> Path | None:
    env = os.environ.get("OBJSEARCH_SHARED")
    candidates = [Path(env), Path(env) / "data"] if env else []
    candidates.append(REPO_ROOT.parent / "shared" / "data")
    for path in candidates:
        if (path / "ai2thor" / "ithor_scenes").is_dir():
            return path
    return None


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The raw shared data; CI always has it beside the clone."""
    path = _shared_data()
    if path is None:
        pytest.skip(
            "raw shared data not found: set OBJSEARCH_SHARED or provide ../shared/data next to "
            "the repository"
        )
    return path
