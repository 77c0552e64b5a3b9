"""Fixtures for the data-converter tests: one build of the shared raw data per session."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from objsearch.pipeline.build import BuildReport, build_data

REPO_ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def built(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, BuildReport]:
    out = tmp_path_factory.mktemp("built")
    return out, build_data(shared_data, out)


@pytest.fixture(scope="session")
def home(built: tuple[Path, BuildReport]) -> dict[str, Any]:
    data: dict[str, Any] = json.loads((built[0] / "homes" / "paper.json").read_text())
    return data
