"""examples/foxglove/objsearch-layout.json, the Foxglove layout shipped for the live view: a layout
file Foxglove imports (panels by id, a split tree of those ids) that names only channels the live
view writes, and plots only numeric fields."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from objsearch.runtime import liveview as lv

LAYOUT = Path(__file__).resolve().parents[2] / "examples" / "foxglove" / "objsearch-layout.json"


def _leaves(node: Any) -> Iterator[str]:
    if isinstance(node, str):
        yield node
    else:
        assert node["direction"] in ("row", "column") and 0 < node["splitPercentage"] < 100
        yield from _leaves(node["first"])
        yield from _leaves(node["second"])


def _topic(path: str) -> str:
    """``/a/b.data`` → ``/a/b`` (a message path's topic)."""
    return path.split(".", 1)[0]


def test_the_layout_names_only_live_channels_and_plots_numbers() -> None:
    doc = json.loads(LAYOUT.read_text(encoding="utf-8"))
    panels = doc["configById"]
    assert sorted(_leaves(doc["layout"])) == sorted(panels)
    assert {p.split("!", 1)[0] for p in panels} == {"3D", "Plot", "RawMessages"}
    three_d = next(c for p, c in panels.items() if p.startswith("3D!"))
    assert three_d["followTf"] == "map"  # the frame every live message is stamped in
    drawn = set(three_d["topics"])
    shown_raw = {lv.SCENE_GRAPH, lv.GRAPH, lv.BELIEF}  # text and typed records, not drawings
    assert drawn == set(lv.CHANNELS) - {lv.DETECTIONS, lv.EVENTS, *shown_raw, *lv.METRICS}
    plotted = [s["value"] for p, c in panels.items() if p.startswith("Plot!") for s in c["paths"]]
    assert sorted(map(_topic, plotted)) == sorted(lv.METRICS)
    assert all(lv.CHANNELS[_topic(v)] == lv.FLOAT64 and v.endswith(".data") for v in plotted)
    raw = [c["topicPath"] for p, c in panels.items() if p.startswith("RawMessages!")]
    assert raw == [f"{lv.SCENE_GRAPH}.data", f"{lv.BELIEF}.places"]
