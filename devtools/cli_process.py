"""The command line in its own process, as a user runs it: the one way the tests and the
batteries start ``python -m objsearch.cli`` (what the process prints, and its exit code, are
what they check)."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path


def run_cli(
    *argv: str,
    env: Mapping[str, str] | None = None,
    cwd: Path | None = None,
    timeout: float = 120,
) -> subprocess.CompletedProcess[str]:
    """``python -m objsearch.cli ARGV`` with this interpreter, its output captured as text.
    ``env`` adds to (and overrides) this process's environment; a run past ``timeout`` seconds
    raises ``subprocess.TimeoutExpired`` (a hung command is a failure, not a result)."""
    return subprocess.run(
        [sys.executable, "-m", "objsearch.cli", *argv],
        capture_output=True,
        text=True,
        cwd=cwd,
        env={**os.environ, **(env or {})},
        timeout=timeout,
        check=False,
    )
