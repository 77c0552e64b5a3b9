"""Fixtures for the data-converter tests: the shared raw data and one build of it per session."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest

from objsearch.pipeline.build import BuildReport, build_data

REPO_ROOT = Path(__file__).resolve().parents[2]


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
    path = _shared_data()
    if path is None:
        pytest.skip(
            "raw shared data not found: set OBJSEARCH_SHARED or provide ../shared/data next to "
            "the repository"
        )
    return path


@pytest.fixture(scope="session")
def built(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, BuildReport]:
    out = tmp_path_factory.mktemp("built")
    return out, build_data(shared_data, out)


@pytest.fixture(scope="session")
def home(built: tuple[Path, BuildReport]) -> dict[str, Any]:
    data: dict[str, Any] = json.loads((built[0] / "homes" / "paper.json").read_text())
    return data
