"""``objsearch demo`` in a pipe: a line at each tenth of its searches (no bar is drawn there)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from objsearch.cli import main


@pytest.mark.slow
def test_the_demo_in_a_pipe_prints_a_line_per_tenth_of_its_searches(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # It said nothing in a pipe until its table: 45 s on a busy machine (issue 47).
    assert main(["demo", "--out", str(tmp_path / "demo"), "--no-baseline"]) == 0
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    pattern = re.compile(r"demo: (\d+) of 640 searches \(\d+ s\)")  # 10 scenes x 8 x 8
    done = [int(m[1]) for m in map(pattern.fullmatch, lines) if m]
    assert done == [64 * i for i in range(1, 11)], lines
    assert "mean, updates" in captured.out and "\r" not in captured.err
