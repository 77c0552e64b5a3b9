"""The build as a whole: deterministic, equal to the committed data, clear errors."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from objsearch.agent.datapaths import data_dir
from objsearch.pipeline.build import PAPER_HOME, BuildReport, build_data, parse_home_arg
from objsearch.pipeline.errors import HomeSpecError, SourceDataError

EXPECTED = {
    "vocabulary.json",
    "priors/visual_genome.json",
    "priors/vg_single_name.json",
    "priors/vg_hoz_masked.json",
    "homes/paper.json",
    "scenarios/table1.json",
    "schedules/table2.json",
    "PROVENANCE.md",
    "priors/ai2thor_placements.json",
    "priors/homer_routines.json",
    *(f"homes/ithor-{i:02d}.json" for i in range(1, 11)),
    *(f"homes/procthor-{i:02d}.json" for i in range(15)),
    "homes/procthor-train1.json",
    *(f"rearrangement/{h}.json" for h in ["paper", *(f"ithor-{i:02d}" for i in range(1, 11))]),
}


def _relative(report: BuildReport, out: Path) -> dict[str, bytes]:
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in report.files}


def test_build_is_deterministic(
    built: tuple[Path, BuildReport], shared_data: Path, tmp_path: Path
) -> None:
    first_out, first = built
    second = build_data(shared_data, tmp_path)
    a, b = _relative(first, first_out), _relative(second, tmp_path)
    assert set(a) == EXPECTED
    assert a == b
    assert all(v.endswith(b"\n") for v in a.values())


def test_committed_data_equals_a_fresh_build(built: tuple[Path, BuildReport]) -> None:
    out, report = built
    committed = data_dir()
    stale = [
        rel
        for rel, content in _relative(report, out).items()
        if not (committed / rel).is_file() or (committed / rel).read_bytes() != content
    ]
    assert not stale, (
        f"data/ differs from the converter's output for {stale}; rebuild with "
        "`objsearch data build --source ../shared/data`"
    )


def test_report_names_every_room(built: tuple[Path, BuildReport]) -> None:
    notes = "\n".join(built[1].notes)
    for room, scene in zip(("kitchen", "living", "bedroom", "bathroom"), PAPER_HOME, strict=True):
        assert f"paper/{room} ({scene})" in notes


def _partial_source(shared: Path, tmp: Path, without: Path) -> Path:
    """A copy of the source tree made of symlinks, lacking one file."""
    root = tmp / "source"
    used = ("ai2thor/ithor_scenes", "ai2thor/alfred_layouts", "vg")
    for path in (p for folder in used for p in (shared / folder).rglob("*")):
        if path.is_file() and path != shared / without:
            link = root / path.relative_to(shared)
            link.parent.mkdir(parents=True, exist_ok=True)
            link.symlink_to(path)
    return root


@pytest.mark.parametrize(
    ("missing", "purpose"),
    [
        (Path("ai2thor/alfred_layouts/FloorPlan303-layout.npy"), "navigation grid of the bedroom"),
        (Path("ai2thor/ithor_scenes/FloorPlan401.json"), "bathroom"),
        (Path("ai2thor/alfred_layouts/FloorPlan2-openable.json"), "ALFRED interaction poses"),
        (Path("vg/VSGM/relationship_matrics_with_word.csv"), "Visual Genome prior"),
    ],
)
def test_missing_source_file_is_named(
    shared_data: Path, tmp_path: Path, missing: Path, purpose: str
) -> None:
    source = _partial_source(shared_data, tmp_path, missing)
    out = tmp_path / "out"
    out.mkdir()
    (out / "vocabulary.json").write_text("old\n")
    with pytest.raises(SourceDataError) as info:
        build_data(source, out)
    assert info.value.path == source / missing
    assert str(source / missing) in str(info.value)
    assert purpose in str(info.value)
    # Nothing is written unless everything could be derived.
    assert (out / "vocabulary.json").read_text() == "old\n"
    assert sorted(os.listdir(out)) == ["vocabulary.json"]


def test_missing_source_folder(tmp_path: Path) -> None:
    with pytest.raises(SourceDataError, match="source folder not found"):
        build_data(tmp_path / "nowhere", tmp_path / "out")


def test_wrong_room_type_is_a_clear_error(shared_data: Path, tmp_path: Path) -> None:
    swapped = ("FloorPlan201", "FloorPlan2", "FloorPlan303", "FloorPlan401")
    with pytest.raises(HomeSpecError) as info:
        build_data(shared_data, tmp_path, homes={"swapped": swapped})
    text = str(info.value)
    assert "kitchen must be a Kitchen scene" in text and "FloorPlan201 is a LivingRoom" in text
    assert not (tmp_path / "homes").exists()


@pytest.mark.parametrize(
    "homes",
    [{"x": ("FloorPlan2", "FloorPlan201", "FloorPlan303")}, {"Bad Name": PAPER_HOME}, {}],
)
def test_malformed_homes_are_refused(
    shared_data: Path, tmp_path: Path, homes: dict[str, tuple[str, ...]]
) -> None:
    with pytest.raises(HomeSpecError):
        build_data(shared_data, tmp_path, homes=homes)


def test_other_homes_build_without_paper_tables(shared_data: Path, tmp_path: Path) -> None:
    report = build_data(
        shared_data,
        tmp_path,
        homes={"second": ("FloorPlan1", "201", "FloorPlan316", "402")},
        accept=["lost-grid-points"],
    )
    names = {p.relative_to(tmp_path).as_posix() for p in report.files}
    assert "homes/second.json" in names and "scenarios/table1.json" not in names
    assert any("FloorPlan316" in n and "23 inside furniture" in n for n in report.notes)
    provenance = (tmp_path / "PROVENANCE.md").read_text()
    assert (
        "--ithor second=FloorPlan1,FloorPlan201,FloorPlan316,FloorPlan402 --accept lost-grid-points"
        in provenance
    )
    assert "schedules/table2.json" not in provenance  # it describes only what it wrote


def test_parse_home_arg() -> None:
    assert parse_home_arg("paper=FloorPlan2,201,FloorPlan303,401") == ("paper", PAPER_HOME)
    with pytest.raises(HomeSpecError):
        parse_home_arg("FloorPlan2,FloorPlan201")
    with pytest.raises(HomeSpecError):
        parse_home_arg("x=Kitchen2,FloorPlan201,FloorPlan303,FloorPlan401")


@pytest.mark.parametrize("name", ["home\n", "home\nx", "home/x"])
def test_home_names_are_checked_whole(name: str) -> None:
    from objsearch.pipeline.home import check_home_spec

    with pytest.raises(HomeSpecError, match="home name"):
        check_home_spec(name, PAPER_HOME)
    assert check_home_spec("home", PAPER_HOME) == PAPER_HOME


def test_every_named_prior_is_built_where_the_agent_reads_it(
    built: tuple[Path, BuildReport],
) -> None:
    from objsearch.agent.session import PRIOR_FILES as READ
    from objsearch.pipeline.vg_prior import PRIOR_FILES as WRITTEN

    out, report = built
    assert READ == WRITTEN
    written = {p.relative_to(out).as_posix() for p in report.files}
    assert set(WRITTEN.values()) <= written


def test_a_home_that_satisfies_the_removal_rule_gets_its_own_table1(
    shared_data: Path, tmp_path: Path
) -> None:
    good = ("FloorPlan3", "FloorPlan203", "FloorPlan310", "FloorPlan402")  # satisfies the rule
    bad = ("FloorPlan1", "201", "FloorPlan316", "402")  # a target left twice or not at all
    report = build_data(
        shared_data, tmp_path, homes={"good": good, "bad": bad}, accept=["lost-grid-points"]
    )
    own = json.loads((tmp_path / "scenarios" / "table1-good.json").read_text())
    assert own["home"] == "good" and len(own["targets"]) == 8
    assert not (tmp_path / "scenarios" / "table1-bad.json").exists()
    assert any(n.startswith("bad: no Table I scenario") for n in report.notes)
