"""Scoring a built semantic map against the truth and by the searches it leads to."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from devtools.cli_process import run_cli
from objsearch.agent.errors import DataFileError
from objsearch.agent.semmap import SemanticMap
from objsearch.agent.session import load_context
from objsearch.sim.mapeval import compare, cost_summary, search_cost
from objsearch.sim.placements import base_placements, table1_removals


def test_the_truth_matches_itself() -> None:
    truth = load_context("paper").semmap
    s = compare(truth, truth).summary()
    assert (s["found"], s["missed"], s["spurious"], s["max_error_m"]) == (45, 0, 0, 0.0)


def test_a_moved_instance_is_missed_and_spurious() -> None:
    truth = load_context("paper").semmap
    statics = list(truth.statics)
    bed = next(i for i, s in enumerate(statics) if s.cls == "Bed")
    box = statics[bed].box
    moved = dataclasses.replace(
        statics[bed],
        box=dataclasses.replace(box, center=(box.center[0] + 3, box.center[1], box.center[2])),
    )
    statics[bed] = moved
    acc = compare(truth, SemanticMap(tuple(statics)))
    assert acc.missed == (moved.id,) and acc.spurious == (moved.id,)


def test_searching_with_the_true_map_as_the_built_one_costs_nothing() -> None:
    ctx = load_context("paper")
    placements = base_placements(ctx.home, table1_removals(ctx.home))
    # Renamed ids check that containers are opened through the map's own names.
    renamed = SemanticMap(
        tuple(dataclasses.replace(s, id=f"built/{i}") for i, s in enumerate(ctx.semmap.statics))
    )
    pairs = search_cost(ctx, renamed, placements, ["Apple", "Bowl"])
    summary = cost_summary(pairs)
    assert summary["searches"] == 16 and summary["success_built"] == 16
    assert summary["path_ratio_built_over_truth"] == 1.0


def test_semantic_map_file_errors() -> None:
    with pytest.raises(DataFileError, match="not a semantic map"):
        SemanticMap.from_json({"format": "x"})
    with pytest.raises(DataFileError, match="malformed"):
        SemanticMap.from_json({"format": "objsearch.semmap/1", "statics": [{"id": 1}]})


def test_map_build_cli(tmp_path: Path) -> None:
    out = tmp_path / "map.json"
    res = run_cli(
        "map",
        "build",
        "--points-per-room",
        "1",
        "--no-search",
        "--format",
        "json",
        "--out",
        str(out),
    )
    assert res.returncode == 0, res.stderr
    report = json.loads(res.stdout)
    assert report["frames"] == 32 and report["accuracy"]["found"] >= 35
    assert SemanticMap.from_json(json.loads(out.read_text())).statics


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("map", "build", "--home", "nowhere"), "no home 'nowhere'"),
        (("map", "build", "--model", "/nonexistent.pt", "--no-search"), "no such file"),
        (("map", "build", "--points-per-room", "0"), "between 1 and 32, not 0"),
        (("map", "show", "--home", "nowhere"), "no home 'nowhere'"),
    ],
)
def test_map_cli_bad_input(args: tuple[str, ...], message: str) -> None:
    res = run_cli(*args)
    assert res.returncode == 2 and message in res.stderr, res.stderr


def test_map_show_json() -> None:
    res = run_cli("map", "show", "--format", "json")
    assert res.returncode == 0
    assert len(json.loads(res.stdout)["statics"]) == 45
