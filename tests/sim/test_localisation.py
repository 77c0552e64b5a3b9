"""The simulated localisation (sim/localisation.py): drift and the localiser's error follow their
parameters, a run replays exactly, a perfect model writes the log it always did, and sightings
are placed from the believed pose."""

from __future__ import annotations

import json
import math
import statistics
from dataclasses import replace
from pathlib import Path

import pytest

from objsearch.agent.geometry import Pose
from objsearch.agent.session import load_context
from objsearch.agent.strategies import RunSpec
from objsearch.cli import main
from objsearch.experiments.golden import FIXED_WALL_CLOCK_NS
from objsearch.sim.localisation import (
    LocalisationModel,
    Localiser,
    localisation_model,
    preset,
    with_localisation,
)
from objsearch.sim.longterm import run_schedule

STEP_M = 0.25  # one grid step, as the robot drives


def _errors(model: LocalisationModel, seed: int, steps: int) -> list[tuple[float, float, float]]:
    loc = Localiser(model, seed)
    out = []
    for _ in range(steps):
        loc.advance(STEP_M)
        out.append(loc.error())
    return out


def test_the_same_seed_gives_the_same_errors_and_another_seed_others() -> None:
    model = preset("realistic")
    assert _errors(model, 7, 200) == _errors(model, 7, 200)
    assert _errors(model, 7, 200) != _errors(model, 8, 200)


def test_odometry_alone_drifts_as_a_random_walk_per_metre() -> None:
    """Without the localiser the error after L metres has variance rate² · L per axis."""
    model = replace(preset("realistic"), localiser=False, jumps_per_m=0.0)
    metres = 16 * STEP_M
    finals = [_errors(model, seed, 16)[-1] for seed in range(3000)]
    var_x = statistics.pvariance([e[0] for e in finals])
    var_y = statistics.pvariance([e[1] for e in finals])
    var_yaw = statistics.pvariance([e[2] for e in finals])
    # 3,000 draws: the sample variance is within ±8 % of the truth at 3 sigma.
    assert var_x == pytest.approx(model.odom_xy_per_sqrt_m**2 * metres, rel=0.08)
    assert var_y == pytest.approx(model.odom_xy_per_sqrt_m**2 * metres, rel=0.08)
    assert var_yaw == pytest.approx(model.odom_yaw_per_sqrt_m**2 * metres, rel=0.08)
    assert abs(statistics.fmean(e[0] for e in finals)) < 0.01  # no bias


def test_the_localiser_bounds_the_error_at_its_rms() -> None:
    """With the localiser (no jumps) the error is stationary: its RMS is the model's, however
    far the robot drives (odometry alone would have drifted to 0.03 · √5000 ≈ 2.1 m)."""
    model = replace(preset("realistic"), jumps_per_m=0.0)
    errors = _errors(model, 3, 20_000)  # 5 km
    rms_x = math.sqrt(statistics.fmean(e[0] ** 2 for e in errors))
    rms_y = math.sqrt(statistics.fmean(e[1] ** 2 for e in errors))
    rms_yaw = math.sqrt(statistics.fmean(e[2] ** 2 for e in errors))
    # ~2,500 correlation lengths: ±10 % holds well beyond 3 sigma.
    assert rms_x == pytest.approx(model.rms_xy, rel=0.1)
    assert rms_y == pytest.approx(model.rms_xy, rel=0.1)
    assert rms_yaw == pytest.approx(model.rms_yaw, rel=0.1)


def test_jumps_come_at_their_rate() -> None:
    model = preset("harsh")
    loc = Localiser(model, 11)
    for _ in range(8000):
        loc.advance(STEP_M)
    expected = model.jumps_per_m * 8000 * STEP_M  # 100
    assert abs(loc.jumps - expected) < 4 * math.sqrt(expected)


def test_a_sighting_is_placed_from_the_believed_pose() -> None:
    loc = Localiser(preset("realistic"), 0)
    loc._fix = (0.1, -0.05, 0.0)  # a known error, no rotation
    believed = Pose(2.0, 3.0, 0.5)
    true = loc.true_pose(believed)
    assert (true.x, true.y) == pytest.approx((1.9, 3.05))
    placed = loc.reconstruct((4.0, 4.0, 0.9), believed)
    assert placed == pytest.approx((4.1, 3.95, 0.9))  # off by the pose error
    loc._fix = (0.0, 0.0, math.radians(90))  # a pure heading error turns it about the robot
    placed = loc.reconstruct((3.0, 3.0, 0.9), believed)
    assert placed == pytest.approx((2.0, 4.0, 0.9))


def test_presets_and_an_unknown_one() -> None:
    assert preset("perfect").perfect
    assert not preset("realistic").perfect and not preset("harsh").perfect
    assert preset("harsh").rms_xy == 2 * preset("realistic").rms_xy
    with pytest.raises(Exception, match="unknown localisation"):
        preset("psychic")


def _spec(localisation: LocalisationModel | None) -> RunSpec:
    ctx = load_context("paper")
    params: dict[str, object] = {"camera": "occluding"}
    if localisation is not None:
        params["localisation"] = localisation.params()
    return RunSpec.of("paper", ctx.home.digest, "wpl", schedule="table2", params=params)


def _run(log: Path, localisation: LocalisationModel | None) -> None:
    run_schedule(
        log,
        _spec(localisation),
        targets=("Apple", "Cup"),
        scenes=(1, 2),
        starts=("kitchen-1", "bedroom-2"),
        wall_clock=lambda: FIXED_WALL_CLOCK_NS,
    )


def _events(log: Path) -> list[dict[str, object]]:
    return [
        json.loads(line.split("\t")[0])
        for line in (log / "events.log").read_text(encoding="utf-8").splitlines()
    ]


def test_perfect_localisation_writes_the_log_it_always_did(tmp_path: Path) -> None:
    _run(tmp_path / "perfect", preset("perfect"))
    _run(tmp_path / "none", None)
    assert (tmp_path / "perfect" / "events.log").read_bytes() == (
        tmp_path / "none" / "events.log"
    ).read_bytes()
    started = next(e for e in _events(tmp_path / "none") if e["type"] == "run_started")
    assert "localisation" not in started["payload"]["params"]  # type: ignore[index]
    spec, localiser = with_localisation(_spec(None))
    assert localiser is None and "localisation" not in spec.params


def test_a_run_with_pose_error_replays_and_places_sightings_off_by_it(tmp_path: Path) -> None:
    _run(tmp_path / "a", preset("harsh"))
    _run(tmp_path / "b", preset("harsh"))
    _run(tmp_path / "perfect", None)
    assert (tmp_path / "a" / "events.log").read_bytes() == (
        tmp_path / "b" / "events.log"
    ).read_bytes()
    events = _events(tmp_path / "a")
    started = next(e for e in events if e["type"] == "run_started")
    recorded = started["payload"]["params"]["localisation"]  # type: ignore[index]
    assert localisation_model(_spec(None).with_changes(params={"localisation": recorded})) == (
        preset("harsh")
    )

    def positions(log: Path) -> dict[str, list[list[float]]]:
        out: dict[str, list[list[float]]] = {}
        for e in _events(log):
            if e["type"] == "detection":
                p = e["payload"]
                out.setdefault(p["instance_id"], []).append(p["position"])  # type: ignore[index]
        return out

    noisy, truth = positions(tmp_path / "a"), positions(tmp_path / "perfect")
    offsets = [
        math.dist(p[:2], truth[i][0][:2]) for i, ps in noisy.items() if i in truth for p in ps
    ]
    assert offsets and max(offsets) > 0.01  # placed off the truth...
    assert statistics.median(offsets) < 1.0  # ...by a pose error, not anywhere


def test_an_unknown_preset_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    for command in (
        ["search", "Apple", "--start", "kitchen-1"],
        ["demo", "--out", "/nonexistent/never-written"],
        ["bench", "homes", "--homes", "paper"],
    ):
        assert main([*command, "--localisation", "psychic"]) == 2
        err = capsys.readouterr().err
        assert "objsearch: error:" in err and "--localisation" in err


@pytest.mark.parametrize(
    "command",
    [["search", "Apple", "--start", "kitchen-1"], ["demo"], ["bench", "homes", "--homes", "paper"]],
)
def test_harsh_localisation_is_an_option_recorded_in_the_run_spec(command: list[str]) -> None:
    from objsearch import cli_types as t
    from objsearch.cli import build_parser

    parse = build_parser().parse_args
    harsh = t.localisation_params(parse([*command, "--localisation", "harsh"]))
    realistic = preset("realistic")
    # The rule: twice realistic's drift and localiser error, five times its jumps, larger ones.
    assert harsh == preset("harsh").params()
    assert harsh["odom_xy_per_sqrt_m"] == 2 * realistic.odom_xy_per_sqrt_m
    assert harsh["rms_yaw"] == 2 * realistic.rms_yaw
    assert harsh["jumps_per_m"] == 5 * realistic.jumps_per_m
    assert harsh["jump_xy"] > realistic.jump_xy and harsh["jump_yaw"] > realistic.jump_yaw
    assert t.localisation_params(parse(command)) is None  # perfect: nothing recorded
