"""``objsearch where`` on an object seen away from every mapped place: the belief's "elsewhere"
carries the room it was seen in, and the text never prints None (issue 47)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from objsearch.agent.where import render
from objsearch.cli import main


@pytest.fixture(scope="module")
def cup_off_the_furniture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Three searches of the paper home that see the Cup on the kitchen floor area, away from
    every mapped place (no --scene: the home's own placements)."""
    log = tmp_path_factory.mktemp("where") / "log"
    for start in ("kitchen-1", "kitchen-2", "living-1"):
        assert main(["search", "Cup", "--start", start, "--log", str(log), "--format", "json"]) == 0
    return log


def test_elsewhere_carries_the_room_it_was_seen_in(
    cup_off_the_furniture: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    assert (
        main(["where", "Cup", str(cup_off_the_furniture), "--at", "last", "--format", "json"]) == 0
    )
    answer = json.loads(capsys.readouterr().out)
    assert answer["last_seen"]["at"] is False and answer["last_seen"]["room"] == "kitchen"
    assert answer["elsewhere"] > 0.9 and answer["elsewhere_room"] == "kitchen"
    rooms = {r["room"]: r["probability"] for r in answer["rooms"]}
    assert max(rooms, key=rooms.__getitem__) == "kitchen"
    assert rooms["kitchen"] >= answer["elsewhere"]
    # Located, elsewhere is inside its room: the rooms alone sum to one.
    assert sum(rooms.values()) == pytest.approx(1.0, abs=1e-3)
    assert answer["usually"]["room"] == "kitchen"


def test_the_text_names_the_room_and_never_none(
    cup_off_the_furniture: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    assert main(["where", "Cup", str(cup_off_the_furniture), "--at", "last"]) == 0
    text = capsys.readouterr().out
    assert "None" not in text
    assert "usually:   away from every mapped place, in kitchen" in text
    assert "rooms:     kitchen 99." in text
    listed = text.split("most likely now", 1)[1].splitlines()[1]
    assert "away from every mapped place, in kitchen" in listed


def _answer(**changes: object) -> dict[str, object]:
    answer: dict[str, object] = {
        "target": "Cup",
        "tasks": 1,
        "time_of_day": None,
        "last_seen": {
            "static_id": None,
            "static_class": None,
            "at": False,
            "position": [0.5, 1.0, 0.9],
            "room": None,
            "task_id": "task-00001",
            "time_ns": 1,
            "scene": None,
        },
        "belief_over_places": 1,
        "elsewhere": 0.8,
        "elsewhere_room": None,
        "evidence": {"episodes": 1.0, "episodes_since_last": None, "weights": {}},
        "usually": {
            "static_id": "(elsewhere)",
            "room": None,
            "episodes": 1.0,
            "share_of_episodes": 1.0,
        },
        "rooms": [{"room": "kitchen", "probability": 0.2}],
        "most_likely_now": [
            {"static_id": "kitchen/Fridge|1", "static_class": "Fridge", "room": "kitchen",
             "probability": 0.2}
        ],
    }  # fmt: skip
    answer.update(changes)
    return answer


def test_an_unknown_room_or_scene_is_said_not_printed_as_none() -> None:
    text = render(_answer())
    assert "None" not in text
    assert "away from every mapped place (room not known)" in text
    assert "elsewhere (room not known) 80.0%" in text
    assert "(task task-00001)" in text
