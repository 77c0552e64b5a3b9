"""Where the project's derived data lives."""

from __future__ import annotations

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent


def data_dir() -> Path:
    """The derived-data folder: ``$OBJSEARCH_DATA`` if set, else ``data/`` in the repository."""
    env = os.environ.get("OBJSEARCH_DATA")
    return Path(env) if env else REPO_ROOT / "data"
