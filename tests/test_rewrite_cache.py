"""tests/conftest.py's ``pytest_collection``: a test module's assert-rewritten bytecode is kept
for the next run even where PYTHONDONTWRITEBYTECODE is set (as on our machines), and only while
the run collects: its tests run with the variable's setting."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent

PROBE = """
import sys


def test_bytecode_is_not_written_while_the_tests_run():
    assert sys.dont_write_bytecode
"""


def test_collection_keeps_the_rewritten_modules_and_the_tests_run_as_the_variable_says(
    tmp_path: Path,
) -> None:
    (tmp_path / "test_probe.py").write_text(PROBE, encoding="utf-8")
    env = os.environ | {"PYTHONDONTWRITEBYTECODE": "1", "PYTHONPATH": str(TESTS)}
    # the suite's conftest as a plugin of a run of its own, in a folder with no other conftest
    argv = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "conftest"]
    run = subprocess.run(
        [*argv, "test_probe.py"], cwd=tmp_path, env=env, capture_output=True, text=True
    )
    assert run.returncode == 0, run.stdout + run.stderr
    [kept] = (tmp_path / "__pycache__").glob("test_probe.*-pytest-*.pyc")
    # the next run reads it: it is not written again
    before = kept.stat().st_mtime_ns
    again = subprocess.run(
        [*argv, "test_probe.py"], cwd=tmp_path, env=env, capture_output=True, text=True
    )
    assert again.returncode == 0, again.stdout + again.stderr
    assert kept.stat().st_mtime_ns == before
