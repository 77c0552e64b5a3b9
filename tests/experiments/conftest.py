"""Fixtures for the experiment tests: the raw shared data some benches build homes from."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def shared() -> Path:
    """``../shared/data`` (or ``$OBJSEARCH_SHARED``); CI always has it beside the clone."""
    env = os.environ.get("OBJSEARCH_SHARED")
    for path in [
        *([Path(env), Path(env) / "data"] if env else []),
        REPO_ROOT.parent / "shared" / "data",
    ]:
        if (path / "ai2thor" / "ithor_scenes").is_dir():
            return path
    pytest.skip("raw shared data not found (../shared/data or OBJSEARCH_SHARED)")
