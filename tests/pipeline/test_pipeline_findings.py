"""Homes the build refuses or reports: a room in pieces, lost grid points, dropped and empty rooms."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from objsearch.cli import main
from objsearch.pipeline.accepted import COMMITTED_FINDINGS
from objsearch.pipeline.build import PAPER_HOME, BuildReport, build_data
from objsearch.pipeline.errors import BuildError
from objsearch.pipeline.findings import (
    DROPPED_ROOMS,
    EMPTY_ROOMS,
    LOST_GRID_POINTS,
    LOST_SHARE_ITHOR,
    SPLIT_ROOMS,
    FindingsError,
    SplitRoomError,
    lost_grid_points,
)
from objsearch.pipeline.procthor import asset_index
from objsearch.pipeline.vocabulary import STATIC_BY_THOR_TYPE

SPLIT_BATHROOM = (*PAPER_HOME[:3], "FloorPlan408")
LOSSY_BEDROOM = ("FloorPlan1", "FloorPlan201", "FloorPlan316", "FloorPlan402")
CLOSED_OFF_HOUSE = Path("procthor_houses/houses_20/house_7.json")


def test_a_room_in_pieces_is_refused_naming_room_pieces_and_remedy(
    shared_data: Path, tmp_path: Path
) -> None:
    with pytest.raises(SplitRoomError) as info:
        build_data(shared_data, tmp_path / "out", homes={"split": SPLIT_BATHROOM})
    text = str(info.value)
    assert "'split'" in text and "bathroom (FloorPlan408)" in text
    assert "2 pieces of 34 and 3 that the robot cannot walk between" in text
    assert "Pick another FloorPlan" in text and "--accept split-rooms" in text
    assert not (tmp_path / "out").exists()


def test_an_accepted_room_in_pieces_keeps_its_largest_piece_and_searches_there_work(
    shared_data: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    out = tmp_path / "out"
    report = build_data(shared_data, out, homes={"split": SPLIT_BATHROOM}, accept=[SPLIT_ROOMS])
    assert [f.key for f, _ in report.findings] == [(SPLIT_ROOMS, "split", "bathroom")]
    (bathroom,) = [
        r
        for r in json.loads((out / "homes" / "split.json").read_text())["rooms"]
        if r["name"] == "bathroom"
    ]
    assert len(bathroom["viewpoints"]) == 34 and bathroom["walkable_components"] == 1
    monkeypatch.setenv("OBJSEARCH_DATA", str(out))
    for start in ("bathroom-1", "bathroom-2"):
        argv = ["search", "--home", "split", "ToiletPaper", "--start", start]
        assert main([*argv, "--scene", "1", "--schedule", "stats-0", "--format", "json"]) == 0
        assert json.loads(capsys.readouterr().out)["success"]


def test_the_cli_refuses_a_room_in_pieces_with_exit_2(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    spec = "split=" + ",".join(SPLIT_BATHROOM)
    code = main(["data", "build", "--source", str(shared_data), "--out", str(out), "--ithor", spec])
    assert code == 2
    err = capsys.readouterr().err
    assert "objsearch: error: home 'split'" in err and "FloorPlan408" in err
    assert "Traceback" not in err and not out.exists()


def test_lost_grid_points_stop_the_build_until_accepted(shared_data: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    with pytest.raises(FindingsError) as info:
        build_data(shared_data, out, homes={"lossy": LOSSY_BEDROOM})
    (finding,) = info.value.findings
    assert finding.key == (LOST_GRID_POINTS, "lossy", "bedroom")
    assert "lost 23 of its 58 grid points" in finding.detail and "Desk 23" in finding.detail
    assert "--accept lost-grid-points" in str(info.value)
    assert not out.exists()

    report = build_data(shared_data, out, homes={"lossy": LOSSY_BEDROOM}, accept=[LOST_GRID_POINTS])
    assert [f.key for f, _ in report.findings] == [finding.key]
    assert f"  - {finding.text()}; accepted: by --accept lost-grid-points" in (
        (out / "PROVENANCE.md").read_text().splitlines()
    )


def test_dropped_rooms_are_reported_as_json_and_refused(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    argv = ["data", "build", "--source", str(shared_data), "--out", str(out), "--format", "json"]
    argv += ["--procthor", f"closed={CLOSED_OFF_HOUSE.as_posix()}"]
    assert main(argv) == 2
    captured = capsys.readouterr()
    refused = json.loads(captured.out)["refused"]
    assert {(f["kind"], f["room"]) for f in refused} == {
        (DROPPED_ROOMS, "kitchen"),
        (DROPPED_ROOMS, "living"),
    }
    assert all("0 are reachable" in f["detail"] for f in refused)
    assert "--accept dropped-rooms" in captured.err and not out.exists()

    assert main([*argv, "--accept", "dropped-rooms"]) == 0
    accepted = json.loads(capsys.readouterr().out)["accepted"]
    assert {f["reason"] for f in accepted} == {"by --accept dropped-rooms"}
    assert (out / "homes" / "closed.json").is_file()


def test_a_room_without_statics_is_an_empty_room(shared_data: Path, tmp_path: Path) -> None:
    house = json.loads((shared_data / "procthor_houses/houses_20/house_0.json").read_text())
    assets = asset_index(shared_data)
    house["objects"] = [
        o for o in house["objects"] if assets[o["assetId"]].object_type not in STATIC_BY_THOR_TYPE
    ]
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps(house))
    with pytest.raises(FindingsError) as info:
        build_data(shared_data, tmp_path / "out", procthor={"bare": bare})
    empty = [f for f in info.value.findings if f.kind == EMPTY_ROOMS]
    assert {f.room for f in empty} == {r["name"] for r in _rooms(shared_data, bare)}
    report = build_data(
        shared_data, tmp_path / "out", procthor={"bare": bare}, accept=[EMPTY_ROOMS]
    )
    assert {f.kind for f, _ in report.findings} == {EMPTY_ROOMS}
    # A house from outside the source folder carries its own hash in the provenance.
    assert "`homes/bare.json`" in (tmp_path / "out" / "PROVENANCE.md").read_text()


def _rooms(shared: Path, house: Path) -> list[dict[str, object]]:
    from objsearch.pipeline.procthor import build_procthor_home

    rooms: list[dict[str, object]] = build_procthor_home(shared, "x", house).doc["rooms"]
    return rooms


def test_the_default_build_accepts_exactly_the_committed_findings(
    built: tuple[Path, BuildReport],
) -> None:
    out, report = built
    assert {f.key for f, _ in report.findings} == set(COMMITTED_FINDINGS)
    lines = (out / "PROVENANCE.md").read_text().splitlines()
    for finding, why in report.findings:
        assert why == COMMITTED_FINDINGS[finding.key]
        assert f"  - {finding.text()}; accepted: {why}" in lines


def test_unknown_kinds_cannot_be_accepted(shared_data: Path, tmp_path: Path) -> None:
    with pytest.raises(BuildError, match="cannot accept everything"):
        build_data(shared_data, tmp_path, homes={"p": PAPER_HOME}, accept=["everything"])


def test_the_lost_share_is_a_strict_threshold() -> None:
    at = lost_grid_points("h", "r", "s", 75, ["Desk"] * 25, 0, LOST_SHARE_ITHOR)
    above = lost_grid_points("h", "r", "s", 74, ["Desk"] * 25, 1, LOST_SHARE_ITHOR)
    assert at is None
    assert above is not None and "26 of its 100" in above.detail and "1 cut off" in above.detail
