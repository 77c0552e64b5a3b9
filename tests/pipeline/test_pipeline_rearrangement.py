"""Rearrangement placements: poses converted like the homes, attributed to the right static."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import pytest

from objsearch.agent.datapaths import data_dir
from objsearch.pipeline import jsonio
from objsearch.pipeline.build import PAPER_HOME
from objsearch.pipeline.errors import SourceDataError
from objsearch.pipeline.geometry import RoomFrame
from objsearch.pipeline.home import SourceHome, build_home
from objsearch.pipeline.more_homes import heldout_candidates
from objsearch.pipeline.rearrangement import (
    REARRANGEMENT,
    Episodes,
    attribute,
    load_episodes,
    pose_center,
    rearrangement_json,
)
from objsearch.pipeline.sources import load_scene
from objsearch.sim.rearr_schedule import read_rearrangement

# Episode 1 of FloorPlan303 (the paper home's bedroom) leaves this laptop where the scene metadata
# has it, on the desk (its parentReceptacles), so the conversion must land on that desk and box.
BEDROOM_LAPTOP = "bedroom/Laptop|-01.76|+00.59|-00.11"
BEDROOM_DESK = "bedroom/Desk|-01.71|+00.00|-00.37"
# Episode 27 of FloorPlan201 (living room): a laptop on the dining table.
LIVING_LAPTOP = "living/Laptop|-01.70|+00.68|+01.66"
LIVING_TABLE = "living/DiningTable|-02.27|-00.02|+01.42"


def _paper(shared_data: Path) -> SourceHome:
    return build_home(shared_data, "paper", PAPER_HOME)


def _committed_target(
    home: str, room: str, episode: int, object_id: str
) -> tuple[list[float], str]:
    doc = json.loads((data_dir() / "rearrangement" / f"{home}.json").read_text())
    r = next(r for r in doc["rooms"] if r["name"] == room)
    k = [o["id"] for o in r["objects"]].index(object_id)
    row = r["episodes"][episode]["target"][k]
    return row[:3], r["statics"][row[3]]


@pytest.mark.parametrize(
    ("room", "episode", "obj", "static"),
    [("bedroom", 1, BEDROOM_LAPTOP, BEDROOM_DESK), ("living", 27, LIVING_LAPTOP, LIVING_TABLE)],
)
def test_known_episode_lands_on_its_static_in_our_frame(
    room: str, episode: int, obj: str, static: str
) -> None:
    home = json.loads((data_dir() / "homes" / "paper.json").read_text())
    placed = next(o for r in home["rooms"] for o in r["objects"] if o["id"] == obj)
    center, support = _committed_target("paper", room, episode, obj)
    assert support == static == placed["support"]
    # The episode's pose is the metadata's pose, so the box lands on the home's own box (REP-103).
    assert max(abs(a - b) for a, b in zip(center, placed["center"], strict=True)) < 2e-3


def test_conversion_from_the_raw_episode(shared_data: Path) -> None:
    home = _paper(shared_data)
    bedroom = next(r for r in home.rooms if r.name == "bedroom")
    scene = load_scene(shared_data, bedroom.source_scene, "test")
    laptop = next(o for o in scene.objects if o.object_id == BEDROOM_LAPTOP.split("/", 1)[1])
    with gzip.open(shared_data / REARRANGEMENT / "2022_train.json.gz", "rt") as fh:
        pose = next(
            p for p in json.load(fh)["FloorPlan303"][1]["target_poses"] if p["name"] == laptop.name
        )
    box = RoomFrame(*bedroom.offset).box(pose_center(laptop, pose), laptop.aabb_size)
    # Unity (x, y, z) -> ROS (z, -x, y) plus the room's offset on the home map.
    ux, uy, uz = pose_center(laptop, pose)
    assert box.center == pytest.approx((uz + bedroom.offset[0], -ux + bedroom.offset[1], uy))
    held = attribute((box.center[0], box.center[1], box.lo[2]), bedroom.statics)
    assert held is not None and held[0].id == BEDROOM_DESK and held[1] < 0.02


def test_attribution_names_the_parent_class_on_the_metadata_poses(shared_data: Path) -> None:
    """Where the scene metadata says what an object rests on, the rule agrees on the class."""
    agree = total = 0
    lists = heldout_candidates(PAPER_HOME)
    homes = [_paper(shared_data)] + [
        build_home(shared_data, f"h{i}", tuple(lists[t][i] for t in range(4))) for i in range(4)
    ]
    for home in homes:
        for room in home.rooms:
            by_id = {s.id: s for s in room.statics}
            for o in room.objects:
                if o.support_rule != "parent":
                    continue
                held = attribute((o.box.center[0], o.box.center[1], o.box.lo[2]), room.statics)
                total += 1
                agree += (
                    held is not None
                    and o.support is not None
                    and held[0].cls == by_id[o.support].cls
                )
    assert total > 40
    assert agree / total >= 0.95


def test_nothing_near_a_static_is_dropped(shared_data: Path) -> None:
    bedroom = next(r for r in _paper(shared_data).rooms if r.name == "bedroom")
    ceiling = (bedroom.statics[0].box.center[0], bedroom.statics[0].box.center[1], 9.0)
    assert attribute(ceiling, bedroom.statics) is None
    assert attribute(ceiling, ()) is None


def test_derived_file_round_trips(shared_data: Path, tmp_path: Path) -> None:
    home = _paper(shared_data)
    scenes = {r.source_scene: load_scene(shared_data, r.source_scene, "test") for r in home.rooms}
    doc, counts = rearrangement_json(home, scenes, load_episodes(shared_data), shared_data)
    text = jsonio.dumps(doc, inline_rows=True)
    assert json.loads(text) == json.loads(jsonio.dumps(doc))  # one-line rows, same content
    path = tmp_path / "paper.json"
    path.write_text(text)
    data = read_rearrangement(path, "paper")
    assert counts.kept + counts.dropped + counts.absent == sum(
        2 * len(r.objects) * len(r.episodes) for r in data.rooms
    )
    for room, raw in zip(data.rooms, doc["rooms"], strict=True):
        assert [o.id for o in room.objects] == [o["id"] for o in raw["objects"]]
        for ep, raw_ep in zip(room.episodes, raw["episodes"], strict=True):
            for k, row in enumerate(raw_ep["target"]):
                pose = ep.target[k]
                assert (pose is None) == (row is None)
                if pose is not None:
                    assert pose.center == pytest.approx(row[:3], abs=1e-4)
                    assert pose.support == raw["statics"][row[3]]
            for k, pose in enumerate(ep.start):
                moved = raw_ep["moved"].get(str(k), raw_ep["target"][k])
                assert (pose is None) == (moved is None)
    assert text == (data_dir() / "rearrangement" / "paper.json").read_text()


def test_missing_or_corrupt_episodes_fail_clearly(tmp_path: Path) -> None:
    with pytest.raises(SourceDataError, match="2022_train"):
        load_episodes(tmp_path)
    folder = tmp_path / REARRANGEMENT
    folder.mkdir(parents=True)
    (folder / "2022_train.json.gz").write_bytes(b"not gzip")
    (folder / "2022_val.json.gz").write_bytes(gzip.compress(b"{}"))
    with pytest.raises(SourceDataError, match="unreadable"):
        load_episodes(tmp_path)


def test_a_floorplan_without_episodes_is_an_error(shared_data: Path) -> None:
    home = _paper(shared_data)
    with pytest.raises(SourceDataError, match="no episodes for FloorPlan2"):
        rearrangement_json(home, {}, Episodes(by_scene={}, files=()), shared_data)
