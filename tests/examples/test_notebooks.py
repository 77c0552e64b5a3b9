"""examples/analytics.ipynb runs headless from top to bottom on a small lake of real simulated
runs, and shows what it promises: each question's table or figure, no cell in error."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any, cast

import nbformat
import pytest
from nbclient import NotebookClient

from objsearch.experiments.sample_lake import write_sample_lake

#: nbformat ships no type hints.
read_notebook = cast(Callable[..., Any], nbformat.read)
NOTEBOOK = Path(__file__).resolve().parents[2] / "examples" / "analytics.ipynb"


def test_the_analytics_notebook_runs_headless(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    lake = write_sample_lake(
        tmp_path / "lake",
        homes=("ithor-01", "procthor-00"),
        scenes=(1, 2),
        targets=("Apple", "Cup"),
    )
    assert len(lake.runs()) == 8
    monkeypatch.setenv("OBJSEARCH_LAKE", str(lake.root))
    monkeypatch.setenv("OBJSEARCH_FIGURES", str(tmp_path / "figures"))
    notebook = read_notebook(NOTEBOOK, as_version=4)
    # The committed notebook carries no outputs (they would go stale): this run makes them.
    assert all(not c.get("outputs") for c in notebook.cells if c.cell_type == "code")
    NotebookClient(
        notebook, timeout=120, kernel_name="python3", resources={"metadata": {"path": tmp_path}}
    ).execute()
    outputs = [o for c in notebook.cells if c.cell_type == "code" for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    shown = [o for o in outputs if o.output_type in ("execute_result", "display_data")]
    figures = [o for o in shown if "image/png" in o.data or "image/svg+xml" in o.data]
    tables = [o for o in shown if "text/html" in o.data and "<table" in o.data["text/html"]]
    # learning curves, drift, the route (SVG); runs, paired, failures, drift's pairs (tables)
    assert len(figures) >= 3 and len(tables) >= 4
    assert "ithor-01-wpl-s0" in tables[0].data["text/html"]
    assert (tmp_path / "figures" / "route.svg").is_file()
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    assert "failed searches of 32" in text and "an interval needs at least 10 pairs" in text


DOC = Path(__file__).resolve().parents[2] / "docs" / "analytics.md"


def test_the_documented_open_analytics_block_runs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    found = re.search(r"```python\n(# open_analytics:.*?)```", DOC.read_text(), re.S)
    assert found is not None
    lake = write_sample_lake(
        tmp_path / "lake", homes=("ithor-01",), strategies=("wpl",), seeds=(0,), scenes=(1,)
    )
    monkeypatch.setenv("OBJSEARCH_LAKE", str(lake.root))
    scope: dict[str, object] = {}
    exec(compile(found.group(1), str(DOC), "exec"), scope)
    per_target = scope["per_target"]
    assert isinstance(per_target, list)
    assert {t for t, _ in per_target} == {"Apple", "Cup", "Phone"}
    assert scope["names"] == ["run", "count_star()"]
    assert scope["rows"] == [("ithor-01-wpl-s0", 3)]
