"""Schedules from real rearrangement episodes: seeded, real poses, fallbacks reported, clear errors."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from objsearch.agent.errors import DataFileError, ObjsearchError
from objsearch.agent.home import load_home
from objsearch.agent.strategies import RunSpec
from objsearch.experiments.homes import homes_jobs
from objsearch.sim.longterm import run_schedule
from objsearch.sim.rearr_schedule import RearrangementData, read_rearrangement, rearr_schedule
from objsearch.sim.schedule_names import UnknownScheduleError, load_schedule
from objsearch.sim.stats_schedule import SCENES, stats_schedule


def test_same_seed_same_schedule_other_seed_differs() -> None:
    home = load_home("ithor-03")
    a, b, c = rearr_schedule(home, 0), rearr_schedule(home, 0), rearr_schedule(home, 1)
    assert a.scenes == b.scenes and a.name == "rearr-0"
    assert a.scenes != c.scenes
    assert sorted(a.scenes) == list(range(1, SCENES + 1))
    assert load_schedule(home, "rearr-0").scenes == a.scenes


def test_fallback_classes_are_reported_and_placed_as_the_stats_draw() -> None:
    home = load_home("paper")
    schedule = rearr_schedule(home, 2, scenes=4)
    # No rearrangement episode has an Apple or a Pillow.
    assert schedule.fallback == ("Apple", "Pillow")
    stats = stats_schedule(home, 2, scenes=4)
    for k, placements in schedule.scenes.items():
        classes = sorted(p.cls for p in placements.values())
        assert len(classes) == len(set(classes)) == 8  # one object per class, all eight targets
        for cls in schedule.fallback:
            mine = [p for p in placements.values() if p.cls == cls]
            assert mine == [p for p in stats.scenes[k].values() if p.cls == cls]


def test_placements_are_real_episode_poses_alternating_target_and_start() -> None:
    home = load_home("ithor-05")
    data = RearrangementData.load("ithor-05")
    schedule = rearr_schedule(home, 0)
    poses = {o.id: (r, k) for r in data.rooms for k, o in enumerate(r.objects)}
    moved_within_pair = 0
    for scene, placements in schedule.scenes.items():
        for p in placements.values():
            if p.cls in schedule.fallback:
                continue
            room, k = poses[p.instance_id]
            phase = "target" if scene % 2 else "start"
            matches = [
                e.index
                for e in room.episodes
                if (pose := getattr(e, phase)[k]) is not None
                and pose.center == p.box.center
                and pose.support == p.support
            ]
            assert matches, f"scene {scene}: {p.instance_id} is not at any {phase} pose"
            assert p.support is not None
            assert p.room == room.name == home.statics[p.support].room
            assert p.inside == home.statics[p.support].container
            if scene % 2 == 0:
                before = schedule.scenes[scene - 1][p.instance_id]
                moved_within_pair += before.box.center != p.box.center
    assert moved_within_pair > 0  # the episodes' own moves show up between scenes 2j-1 and 2j


def test_homes_without_rearrangement_data_are_refused_with_the_alternative() -> None:
    with pytest.raises(DataFileError, match="stats-<seed>"):
        rearr_schedule(load_home("procthor-01"), 0)
    with pytest.raises(ObjsearchError, match=r"procthor-01.*--schedules stats"):
        homes_jobs(["ithor-01", "procthor-01"], ["wpl"], 1, schedules=["rearr"])


def test_unknown_schedules_are_errors() -> None:
    home = load_home("ithor-01")
    with pytest.raises(UnknownScheduleError, match="rearr-<seed>"):
        load_schedule(home, "weekly")
    with pytest.raises(UnknownScheduleError, match="integer seed"):
        load_schedule(home, "rearr-x")
    with pytest.raises(UnknownScheduleError, match="expected a comma-separated subset"):
        homes_jobs(["ithor-01"], ["wpl"], 1, schedules=["rearr", "daily"])


def test_jobs_name_one_schedule_per_kind_and_seed() -> None:
    jobs = homes_jobs(["ithor-01"], ["wpl", "epl"], 2, scenes=1, schedules=["rearr", "stats"])
    assert sorted({j.placements for j in jobs}) == ["rearr-0", "rearr-1", "stats-0", "stats-1"]
    assert len(jobs) == 4 * 3  # wpl, epl, and the wpl/none baseline


def test_a_malformed_file_is_a_clear_error(tmp_path: Path) -> None:
    path = tmp_path / "paper.json"
    path.write_text(json.dumps({"format": "objsearch.rearrangement/1", "home": "paper"}))
    with pytest.raises(DataFileError, match="malformed"):
        read_rearrangement(path, "paper")
    path.write_text("{")
    with pytest.raises(DataFileError, match="not valid JSON"):
        read_rearrangement(path, "paper")


def test_the_long_term_runner_accepts_rearr_schedules(tmp_path: Path) -> None:
    trials = run_schedule(
        tmp_path,
        RunSpec.for_home(load_home("ithor-01"), "wpl", schedule="rearr-0"),
        targets=["Cup", "Apple"],
        scenes=[1, 2],
        starts=["kitchen-1"],
    )
    assert [(t.scene, t.target) for t in trials] == [
        (1, "Cup"),
        (1, "Apple"),
        (2, "Cup"),
        (2, "Apple"),
    ]
    assert all(t.success for t in trials)
