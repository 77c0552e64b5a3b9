"""The decomposition of the routine metric: the schedule's slot effect and where paths go."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.experiments.routine_ceiling import path_split, slot_effect
from objsearch.experiments.runner import Row


def test_knowing_the_slot_never_makes_the_likeliest_place_less_likely() -> None:
    effect = slot_effect(["ithor-01"], 1)
    assert set(effect) == {
        "place_blind_mode",
        "place_slot_mode",
        "room_blind_mode",
        "room_slot_mode",
        "room_mode_differs",
    }
    assert 0 < effect["place_blind_mode"] <= effect["place_slot_mode"] <= 1
    assert effect["place_slot_mode"] >= 0.7  # the slot's usual place alone holds 0.7
    assert effect["room_blind_mode"] <= effect["room_slot_mode"] <= 1
    assert 0 <= effect["room_mode_differs"] <= 1


def _row(scene: int, target: str, path: float, wrong: float) -> Row:
    return Row(
        "homes", "h", "routine-0", "s", "all", 0, scene, target, "a", True, path, 2.0, "t",
        wrong_rooms_m=wrong,
    )  # fmt: skip


def test_the_first_search_of_a_scene_is_split_from_the_later_ones() -> None:
    rows = [
        _row(57, "Cup", 6.0, 3.0),  # Apple absent: Cup is the scene's first search
        _row(57, "Bowl", 2.0, 0.0),
        _row(58, "Apple", 4.0, 1.0),
        _row(58, "Cup", 3.0, 0.0),
        _row(56, "Apple", 100.0, 50.0),  # before the evaluated days
    ]
    split = path_split(rows)["s"]
    assert split["searches"] == 4
    assert split["first_of_scene_ratio"] == pytest.approx((6 + 4) / 4)
    assert split["later_ratio"] == pytest.approx((2 + 3) / 4)
    assert split["straight_share"] == 0.5
    assert split["excess_straight_m"] == pytest.approx(0.5)
    assert split["excess_detour_m"] == pytest.approx(3.0)


def test_the_homer_slot_effect_is_read_from_the_homer_routines() -> None:
    effect = slot_effect(["ithor-01"], 1, kind="homer")
    assert 0 < effect["place_blind_mode"] <= effect["place_slot_mode"] <= 1
    assert effect["room_blind_mode"] <= effect["room_slot_mode"] <= 1
    assert effect != slot_effect(["ithor-01"], 1)


def test_bench_routine_ceiling_takes_the_routine_kinds_and_refuses_other_folders(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from objsearch.cli import build_parser, main
    from objsearch.sim.schedule_names import ROUTINE_KINDS

    args = build_parser().parse_args(["bench", "routine-ceiling", str(tmp_path), "--kind", "homer"])
    assert args.kind == "homer"
    with pytest.raises(SystemExit) as exit_info:
        build_parser().parse_args(["bench", "routine-ceiling", str(tmp_path), "--kind", "stats"])
    assert exit_info.value.code == 2
    assert f"choose from {', '.join(map(repr, ROUTINE_KINDS))}" in capsys.readouterr().err
    assert main(["bench", "routine-ceiling", str(tmp_path)]) == 2
    assert "not a bench homes output" in capsys.readouterr().err
