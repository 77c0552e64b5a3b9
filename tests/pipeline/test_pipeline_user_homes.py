"""A home a user brings: ``data build --ithor/--procthor/--heldout-ithor`` writes a data folder that
``search`` and ``bench homes`` run on, and keeps the provenance of a folder it adds to."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from objsearch.agent.datapaths import data_dir
from objsearch.agent.errors import ObjsearchError
from objsearch.cli import main
from objsearch.experiments.homes import homes_jobs
from objsearch.pipeline.build import build_data
from objsearch.pipeline.provenance import merge_provenance

#: The committed held-out home ithor-02's FloorPlans and the house of procthor-03, under new names.
ITHOR_02 = "FloorPlan18,FloorPlan217,FloorPlan323,FloorPlan418"
HOUSE_3 = "procthor_houses/houses_20/house_3.json"


@pytest.fixture(scope="module")
def user_data(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("user-data")
    argv = ["data", "build", "--source", str(shared_data), "--out", str(out)]
    argv += ["--ithor", f"user-flat={ITHOR_02}", "--procthor", f"user-house={HOUSE_3}"]
    assert main(argv) == 0
    return out


def test_one_home_makes_a_folder_search_and_bench_homes_run_on(
    user_data: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert (user_data / "priors" / "ai2thor_placements.json").is_file()
    assert (user_data / "rearrangement" / "user-flat.json").is_file()
    monkeypatch.setenv("OBJSEARCH_DATA", str(user_data))
    capsys.readouterr()
    for home, schedule in (("user-flat", "rearr-0"), ("user-house", "stats-0")):
        argv = ["search", "--home", home, "Cup", "--start", "kitchen-1"]
        assert main([*argv, "--scene", "2", "--schedule", schedule, "--format", "json"]) == 0
        assert json.loads(capsys.readouterr().out)["success"]
    bench = ["bench", "homes", "--out", str(tmp_path / "bench"), "--homes", "user-flat,user-house"]
    bench += [
        "--strategies",
        "wpl",
        "--scenes-per-schedule",
        "1",
        "--workers",
        "1",
        "--no-progress",
    ]
    assert main([*bench, "--schedules", "stats,rearr"]) == 2
    assert "user-house is a ProcTHOR house (procthor_houses/houses_20/house_3.json)" in (
        capsys.readouterr().err
    )
    assert main([*bench, "--schedules", "stats", "--format", "json"]) == 0
    summary = json.loads((tmp_path / "bench" / "summary.json").read_text())
    assert set(summary["by_home"]) == {"user-flat", "user-house"}


def test_a_fresh_folder_lists_exactly_what_it_holds(user_data: Path) -> None:
    text = (user_data / "PROVENANCE.md").read_text()
    listed = text.split("## Derived files\n\n", 1)[1].split("\n\n", 1)[0].splitlines()
    held = sorted(
        p.relative_to(user_data).as_posix() for p in user_data.rglob("*.json") if p.is_file()
    )
    assert listed == [f"- `{f}`" for f in held]
    assert f"--ithor user-flat={ITHOR_02} --procthor user-house={HOUSE_3}" in text


def test_an_ithor_home_without_episodes_names_its_floorplans(
    user_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    copy = tmp_path / "data"
    shutil.copytree(user_data, copy)
    (copy / "rearrangement" / "user-flat.json").unlink()
    monkeypatch.setenv("OBJSEARCH_DATA", str(copy))
    with pytest.raises(ObjsearchError) as info:
        homes_jobs(["user-flat"], ["wpl"], 1, schedules=["rearr"])
    assert f"user-flat: no rearrangement episodes were derived for its FloorPlans {ITHOR_02}" in (
        str(info.value).replace(", ", ",")
    )


def test_adding_a_home_keeps_every_line_of_the_folders_provenance(
    shared_data: Path, tmp_path: Path
) -> None:
    out = tmp_path / "data"
    out.mkdir()
    old = (data_dir() / "PROVENANCE.md").read_bytes()
    (out / "PROVENANCE.md").write_bytes(old)
    build_data(shared_data, out, procthor={"added": Path(HOUSE_3)})
    new = (out / "PROVENANCE.md").read_bytes()
    assert new.startswith(old)
    added = new[len(old) :].decode()
    assert "## Added by `objsearch data build --source ../shared/data --procthor added=" in added
    assert "- `homes/added.json`" in added and "`homes/added.json`: `" in added
    # The house file was already listed with its hash, the priors too: not repeated.
    assert f"  - `{HOUSE_3}` `" not in added and "priors/" not in added
    # Building the same again adds nothing.
    build_data(shared_data, out, procthor={"added": Path(HOUSE_3)})
    assert (out / "PROVENANCE.md").read_bytes() == new


def test_merging_keeps_old_bytes_even_without_a_final_newline() -> None:
    old = "# P\n\n## Derived files\n\n- `a.json`"
    new = "# P\n\n## Derived files\n\n- `a.json`\n- `b.json`\n"
    merged = merge_provenance(old, new, "cmd")
    assert merged.startswith(old + "\n")
    assert merged.endswith("## Added by `cmd`\n\n### Derived files\n\n- `b.json`\n")
    assert merge_provenance(merged, new, "cmd") == merged


def test_committed_homes_rebuild_byte_identically_from_their_options(
    shared_data: Path, tmp_path: Path
) -> None:
    build_data(
        shared_data,
        tmp_path,
        heldout_ithor=[2],
        procthor={"procthor-03": Path(HOUSE_3)},
    )
    for rel in ("homes/ithor-02.json", "rearrangement/ithor-02.json", "homes/procthor-03.json"):
        assert (tmp_path / rel).read_bytes() == (data_dir() / rel).read_bytes(), rel
    assert not (tmp_path / "homes" / "ithor-01.json").exists()


def test_a_name_given_twice_is_refused(shared_data: Path, tmp_path: Path) -> None:
    with pytest.raises(ObjsearchError, match="ithor-02 asked for twice"):
        build_data(
            shared_data,
            tmp_path,
            homes={"ithor-02": ITHOR_02.split(",")},
            heldout_ithor=[2],
        )
