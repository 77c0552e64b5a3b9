"""The HOMER step of the converter: places at the schedules' times of day, counted over days."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from objsearch.pipeline.errors import SourceDataError
from objsearch.pipeline.homer import (
    HOMER,
    HOUSEHOLDS,
    SLOT_MINUTES,
    homer_routines_json,
    household_routines,
)

#: node index: 0 kitchen (room), 1 kitchen_counter, 2 cupboard, 3 mug, 4 tray (movable), 5 apple.
NODES: dict[str, Any] = {
    "node_ids": [1, 10, 20, 100, 101, 102],
    "node_classes": ["dining_room", "kitchen_counter", "cupboard", "mug", "tray", "food_apple"],
    "node_categories": [
        "Rooms",
        "Furniture",
        "Furniture",
        "placable_objects",
        "placable_objects",
        "placable_objects",
    ],
    "info": {"search_object_names": ["mug", "food_apple", "spoon"]},
}


def _day(name: str, changes: list[list[int]]) -> dict[str, Any]:
    # Everything starts in the cupboard; the tray lies on the counter.
    return {"file": name, "start": [-1, 0, 0, 2, 1, 2], "changes": changes}


def _source(tmp: Path, days: list[dict[str, Any]], nodes: dict[str, Any] = NODES) -> Path:
    for h in HOUSEHOLDS:
        folder = tmp / HOMER / h
        folder.mkdir(parents=True)
        (folder / "common_data.json").write_text(json.dumps(nodes))
        (folder / "days.json").write_text(json.dumps({"days": days}))
    return tmp


def test_places_are_counted_at_each_time_of_day(tmp_path: Path) -> None:
    morning, afternoon = SLOT_MINUTES[0], SLOT_MINUTES[1]
    days = [
        # The mug goes onto the tray (so: the counter) before the morning slot and back at noon.
        _day("train/000.pt", [[morning - 10, 3, 4], [afternoon - 30, 3, 2]]),
        # Later: still on the tray in the afternoon; the apple is on the counter all day.
        _day("train/001.pt", [[morning, 3, 4], [afternoon + 10, 3, 2], [400, 5, 1]]),
    ]
    out = household_routines(_source(tmp_path, days), "household0")
    assert out["days"] == ["train/000.pt", "train/001.pt"]
    assert out["places"] == {"10": "kitchen_counter", "20": "cupboard"}
    mug = out["routines"]["mug"]
    assert mug[0] == {"10": 2}  # a change at the slot's minute counts
    assert mug[1] == {"10": 1, "20": 1}
    assert mug[2] == mug[3] == {"20": 2}
    assert out["routines"]["food_apple"][0] == {"10": 1, "20": 1}
    assert "spoon" not in out["routines"]  # a search object the graph does not hold
    assert out["halves"]["mug"] == [
        [{"10": 1}, {"20": 1}, {"20": 1}, {"20": 1}],
        [
            {"10": 1},
            {"10": 1},
            {"20": 1},
            {"20": 1},
        ],
    ]
    doc = homer_routines_json(tmp_path)
    assert doc["slot_minutes"] == list(SLOT_MINUTES)
    assert doc["summary"]["cells"] == 5 * 2 * 4
    assert 0 < doc["summary"]["half_mode_change"] < 1


def test_a_place_without_a_mapping_is_refused(tmp_path: Path) -> None:
    nodes = {
        **NODES,
        "node_classes": [*NODES["node_classes"][:2], "hammock", *NODES["node_classes"][3:]],
    }
    with pytest.raises(SourceDataError, match="hammock"):
        household_routines(_source(tmp_path, [_day("train/000.pt", [])], nodes), "household0")


def test_a_missing_household_is_named(tmp_path: Path) -> None:
    with pytest.raises(SourceDataError, match="household0"):
        homer_routines_json(tmp_path)
