"""Fixtures every test package may use: the raw shared data (``../shared/data`` beside the clone,
or ``$OBJSEARCH_SHARED``), which the data converter and the FloorPlan-set benches build homes from,
and torch on one thread for the modules that fuse maps in the test process."""

from __future__ import annotations

import os
from collections.abc import Iterator
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


@pytest.fixture(scope="module")
def one_torch_thread() -> Iterator[None]:
    """Fuse on one thread, as ``objsearch map build`` does by default (``--threads 1``): with two
    OpenMP threads on a 2-core machine that other processes share, torch waits on its thread
    barrier (tests/agent/test_mapping.py's paper-home map: 47 s with two threads at load 7, 8 s
    with one). Imported here, not above: most tests never load torch."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
