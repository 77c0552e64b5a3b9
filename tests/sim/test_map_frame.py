"""A new map whose frame moves (sim/map_frame.py): drawn from the seed and recorded, the robot
reports in it, the agent registers it and decides as in the old frame, and ``where`` flags
every answer resting on the old map."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.maps import map_of
from objsearch.agent.session import load_context
from objsearch.agent.strategies import RunSpec
from objsearch.agent.where import where
from objsearch.cli import main
from objsearch.events.log_read import read_log
from objsearch.experiments.golden import FIXED_WALL_CLOCK_NS
from objsearch.sim.localisation import preset
from objsearch.sim.longterm import Trial, run_schedule
from objsearch.sim.map_frame import draw_frame, frame_mode, recorded_frame

TARGETS = ("Apple", "Cup", "Vase")


def test_a_frame_is_drawn_from_the_seed_and_the_map() -> None:
    a = draw_frame(0, "map-1")
    assert a == draw_frame(0, "map-1")
    assert a != draw_frame(1, "map-1") and a != draw_frame(0, "map-2")
    assert recorded_frame({"map_frame": a.params()}) == a and recorded_frame({}) is None
    frames = [draw_frame(s, "map-1") for s in range(200)]
    assert all(-math.pi <= f.yaw < math.pi and abs(f.x) <= 5 and abs(f.y) <= 5 for f in frames)
    assert max(abs(f.yaw) for f in frames) > 2.5  # any heading, not small turns only
    assert frame_mode({}) == "same" and frame_mode({"new_map_frame": "moved"}) == "moved"
    with pytest.raises(ObjsearchError, match="unknown new-map frame"):
        frame_mode({"new_map_frame": "sideways"})


def _run(log: Path, home: str, frame: str | None, **params: Any) -> list[Trial]:
    ctx = load_context(home)
    extra = {} if frame is None else {"new_map_frame": frame}
    spec = RunSpec.of(
        home,
        ctx.home.digest,
        "global-belief",
        schedule="habit-0",
        params={"camera": "occluding", "new_map_day": 3, **extra, **params},
    )
    return run_schedule(
        log,
        spec,
        targets=TARGETS,
        scenes=(1, 2, 3, 4),
        starts_per_search=1,
        wall_clock=lambda: FIXED_WALL_CLOCK_NS,
    )


def _events(log: Path) -> list[dict[str, Any]]:
    return [
        json.loads(line.split("\t")[0])
        for line in (log / "events.log").read_text(encoding="utf-8").splitlines()
    ]


def _rounded(value: Any) -> Any:
    if isinstance(value, float):
        return round(value, 6)
    if isinstance(value, list):
        return [_rounded(v) for v in value]
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    return value


@pytest.mark.parametrize(
    ("home", "params"),
    [("ithor-02", {}), ("procthor-00", {"localisation": preset("realistic").params()})],
)
def test_the_agent_registers_a_moved_map_and_decides_as_in_the_old_frame(
    tmp_path: Path, home: str, params: dict[str, Any]
) -> None:
    same = _run(tmp_path / "same", home, None, **params)
    moved = _run(tmp_path / "moved", home, "moved", **params)
    _run(tmp_path / "again", home, "moved", **params)
    assert (tmp_path / "moved" / "events.log").read_bytes() == (
        tmp_path / "again" / "events.log"
    ).read_bytes()  # the frame is drawn from the seed: the run replays exactly
    started = [e for e in _events(tmp_path / "moved") if e["type"] == "run_started"]
    assert [map_of(e["payload"]["params"]) for e in started] == ["map-0", "map-1"]
    assert "map_frame" not in started[0]["payload"]["params"]
    frame = recorded_frame(started[1]["payload"]["params"])
    assert frame == draw_frame(0, "map-1")
    # Re-anchored by its statics, the new map's searches are the old frame's: the same paths and
    # outcomes, and every event (poses, detections' positions) the same to a micrometre.
    assert [(t.path_length, t.success, t.target) for t in moved] == [
        (t.path_length, t.success, t.target) for t in same
    ]
    assert any(t.scene >= 3 for t in moved)

    def rest(log: Path) -> list[Any]:
        return [_rounded(e["payload"]) for e in _events(log) if e["type"] != "run_started"]

    assert rest(tmp_path / "moved") == rest(tmp_path / "same")
    # Every class seen in map-0 rests on the map the robot left: flagged.
    for target in TARGETS:
        answer = where(read_log(tmp_path / "moved", store=STORE), target)
        maps = answer["map"]
        assert isinstance(maps, dict) and maps["current"] == "map-1"
        if any(e["map"] == "map-0" for e in maps["evidence"]):
            assert maps["flagged"] and "map-0" in maps["flag"], target


def test_a_run_that_names_no_frame_keeps_the_old_one(tmp_path: Path) -> None:
    _run(tmp_path / "none", "paper", None)
    params = [
        e["payload"]["params"] for e in _events(tmp_path / "none") if e["type"] == "run_started"
    ]
    assert [map_of(p) for p in params] == ["map-0", "map-1"]
    assert all("map_frame" not in p and "new_map_frame" not in p for p in params)


def test_bench_homes_validates_the_frame_option(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    command = ["bench", "homes", "--homes", "paper", "--out", str(tmp_path / "out")]
    assert main([*command, "--new-map-day", "2", "--new-map-frame", "sideways"]) == 2
    err = capsys.readouterr().err
    assert "objsearch: error:" in err and "--new-map-frame" in err
    assert main([*command, "--new-map-frame", "moved"]) == 2
    err = capsys.readouterr().err
    assert "objsearch: error:" in err and "new map" in err
