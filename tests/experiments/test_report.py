"""``bench report`` from small real bench outputs: every section the issues ask for is on the page
(with the command that produced its input), and a missing optional input leaves its section out
with the command that would produce it."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from pathlib import Path

import pytest

from objsearch.cli import main
from objsearch.experiments.learning import paired_differences
from objsearch.experiments.paper import discovery
from objsearch.experiments.report_homes import failure_lines, update_regressions
from objsearch.experiments.report_paper import cameras_section
from objsearch.experiments.runner import read_rows

from .browser import IMAGES_RENDERED, Browser, check_screenshot


def _bench(*argv: str) -> None:
    assert main([*argv, "--workers", "1", "--no-progress"]) == 0


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("bench")
    out = {name: root / name for name in ("paper", "homes", "heldout")}
    _bench(
        *["bench", "paper", "--out", str(out["paper"]), "--targets", "Apple,Vase"],
        *["--scenes", "1", "--sdp-seeds", "2", "--strategies", "sdp,wpl", "--keep-logs"],
    )
    _bench(
        *["bench", "homes", "--out", str(out["homes"]), "--homes", "procthor-00,ithor-01"],
        *["--scenes-per-schedule", "2", "--strategies", "wpl,epl"],
    )
    _bench(
        *["bench", "homes", "--out", str(out["heldout"]), "--homes", "ithor-02"],
        *["--scenes-per-schedule", "1", "--strategies", "wpl"],
    )
    return out


def _report(runs: dict[str, Path], tmp_path: Path, *extra: str) -> str:
    page = tmp_path / "docs" / "results.md"
    argv = ["bench", "report", "--paper", str(runs["paper"]), "--evaluation", str(runs["homes"])]
    argv += ["--out", str(page), "--img", str(tmp_path / "docs" / "img"), *extra]
    assert main(argv) == 0
    return page.read_text(encoding="utf-8")


def test_bench_summaries_record_their_commands(runs: dict[str, Path]) -> None:
    paper = json.loads((runs["paper"] / "summary.json").read_text())
    homes = json.loads((runs["homes"] / "summary.json").read_text())
    assert paper["command"] == (
        f"objsearch bench paper --out {runs['paper']} --strategies sdp,wpl --sdp-seeds 2 "
        "--targets Apple,Vase --scenes 1 --keep-logs --workers 1"
    )
    assert homes["command"] == (
        f"objsearch bench homes --out {runs['homes']} --homes procthor-00,ithor-01 "
        "--schedules stats --seeds 1 --scenes-per-schedule 2 --strategies wpl,epl --workers 1"
    )
    assert homes["prior"] == "vg-cooccurrence"


def test_without_optional_inputs_their_sections_say_how_to_produce_them(
    runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = _report(runs, tmp_path)
    capsys.readouterr()
    # Table I and II by the paper's metric, the full path and the paper's figures beside.
    assert "path length to discovery (m; the paper's metric)" in text
    assert "path+appr" in text and "[10.04]" in text and "-25.27 %" in text
    assert "--keep-logs --workers 1`" in text  # the paper run's command
    assert "prior `vg-cooccurrence`" in text and "Camera: occluding" in text
    assert "![scene graph](img/scene_graph_before_after.png)" in text
    for missing in ("bench table1 --sets 100", "--heldout out/bench-heldout", "--paper-geometric"):
        assert missing in text
    assert text.count("Not in this report:") == 3
    # The homes section: every figure issue 16 asks for.
    assert "## Homes (not tuned on)" in text
    assert "objsearch bench homes --out" in text and "--schedules stats --seeds 1" in text
    for heading in (
        "| strategy | path to discovery m | full path m | oracle× all | oracle× first of day",
        "| strategy | full path m | oracle m | excess m | wrong rooms m | of which start room m "
        "| right room m | approach m | wrong rooms share of the path |",
        "![homes_stats](img/homes_stats.png)",
        "| strategy | Δ path to discovery vs wpl (wpl+cover for a cover run) m | 95 % CI (or "
        "the range, under 10 runs) | runs |",
        # Two runs (one per home): the range and n, never a "95 % CI" over 2 runs.
        "(no CI: < 10 runs) | 2 |",
        "updates made it longer than wpl/none in **",
        "Success 100.00 % (768 of 768 searches); no failures.",
        "### Home family: ithor",
        "### Home family: procthor",
        "### Schedule kind: stats",
    ):
        assert heading in text, heading
    for suffix in (".png", ".svg", ".pdf"):  # every figure also as SVG and PDF
        assert (tmp_path / "docs" / "img" / "homes_stats").with_suffix(suffix).stat().st_size > 0
        assert (tmp_path / "docs" / "img" / "homes_per_home").with_suffix(suffix).is_file()
    assert "| epl |" in text and "| wpl/none |" in text


def test_every_optional_section_from_its_own_run(
    runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], shared_data: Path
) -> None:
    t1, masked = tmp_path / "table1", tmp_path / "table1-masked"
    for out, prior_option in ((t1, []), (masked, ["--prior", "vg-hoz-masked"])):
        _bench(
            *["bench", "table1", "--sets", "1", "--seed", "1", "--out", str(out), *prior_option],
            *["--source", str(shared_data), "--targets", "Cup"],
        )
    text = _report(
        runs,
        tmp_path,
        *("--table1", str(t1), "--table1", str(masked), "--heldout", str(runs["heldout"])),
        *("--paper-geometric", str(runs["paper"])),
    )
    capsys.readouterr()
    assert "Not in this report:" not in text
    assert text.count("## Table I over FloorPlan sets") == 1
    assert f"objsearch bench table1 --sets 1 --seed 1 --source {shared_data}" in text
    assert "| strategy | median | IQR (25–75 %) | 5–95 % | mean | paper (percentile) |" in text
    # One comparison row and one section per reading of Eq. 2.
    assert "| prior | sets | SDP | RVP | WPL | paper's order |" in text
    for prior in ("vg-cooccurrence", "vg-hoz-masked"):
        assert f"### Prior `{prior}`" in text and f"| {prior} | 1 |" in text
    held = text.split("## Held-out homes (looked at only at the end)")[1]
    homes = text.split("## Homes (not tuned on)")[1].split("## Held-out")[0]
    assert "Homes (1): ithor-02." in held and "ithor-02" not in homes
    assert "![heldout_stats](img/heldout_stats.png)" in held
    # Both runs used the same camera: the section says there is nothing to compare.
    assert "Both runs used the occluding camera" in text


def test_heldout_must_not_be_the_homes_run(
    runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["bench", "report", "--paper", str(runs["paper"]), "--evaluation", str(runs["homes"])]
    argv += ["--heldout", str(runs["homes"]), "--out", str(tmp_path / "r.md")]
    assert main(argv) == 2
    assert "held-out homes are reported apart" in capsys.readouterr().err


def test_the_camera_difference_per_strategy(runs: dict[str, Path]) -> None:
    summary = json.loads((runs["paper"] / "summary.json").read_text())
    geometric = {**summary, "camera": "geometric"}
    occluding = {**summary, "camera": "occluding"}
    wpl = occluding["table1"]["wpl"]
    occluding["table1"] = {**occluding["table1"], "wpl": {**wpl, "mean_path_to_discovery": 30.0}}
    text = cameras_section(occluding, geometric, runs["paper"])
    assert "## The camera: occluding against geometric" in text
    before = wpl["mean_path_to_discovery"]
    assert f"| table1 | wpl | 30.00 | {before:.2f} | {before - 30.0:+.2f} |" in text
    assert "| longterm | wpl/all |" in text


def test_failures_are_listed_with_their_cause(runs: dict[str, Path]) -> None:
    rows = read_rows(runs["homes"] / "homes_trials.parquet")
    failed = dataclasses.replace(rows[0], success=False)
    lines = failure_lines([failed, *rows[1:]])
    assert lines[0].startswith(f"Success {100 * (len(rows) - 1) / len(rows):.2f} %")
    row = lines[-1]
    r = failed
    assert row.startswith(
        f"| {r.home} | {r.placements} | {r.scene} | {r.target} | {r.strategy} ×1 |"
    )
    # A target the runs did find is detectable from its static's viewpoint: the cause says so.
    assert "detectable from its static's viewpoint (" in row and "not detected" in row
    # Failures of one placement from several starts are one line, counted by strategy.
    twice = [failed, dataclasses.replace(failed, start="other"), *rows[1:]]
    assert failure_lines(twice)[-1].startswith(row.split(" ×1 |")[0].rsplit("|", 1)[0])
    assert f"| {r.strategy} ×2 |" in failure_lines(twice)[-1]


def test_update_regressions_count_runs_against_the_no_update_twin(
    runs: dict[str, Path],
) -> None:
    rows = read_rows(runs["homes"] / "homes_trials.parquet")
    longer, total = update_regressions(rows)["wpl"]
    assert total == 2 and 0 <= longer <= total
    assert set(update_regressions(rows)) == {"wpl"}  # epl ran without a no-update twin


def test_report_dirs_are_checked(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["bench", "report", "--paper", str(tmp_path), "--evaluation", str(tmp_path)]
    assert main([*argv, "--table1", str(tmp_path / "nowhere")]) == 2
    assert "no such folder" in capsys.readouterr().err
    assert main([*argv, "--out", str(tmp_path / "r.md")]) == 2
    assert "no bench summary" in capsys.readouterr().err
    assert not os.path.exists(tmp_path / "r.md")


def test_a_report_of_homes_alone_needs_no_paper_run(
    runs: dict[str, Path],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    # A data folder of one's own homes is reported on its own (out/bench-paper is not here).
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "report", "--evaluation", str(runs["homes"]), "--no-progress"]) == 0
    text = Path("out/report/results.md").read_text(encoding="utf-8")
    reproduce = text.split("```sh\n", 1)[1].split("```", 1)[0]
    assert "objsearch bench paper" not in reproduce and "--paper" not in reproduce
    assert "Not in this report: run `objsearch bench paper --out out/bench-paper`" in text
    assert "## Homes (not tuned on)" in text and "Homes (2): ithor-01, procthor-00." in text
    capsys.readouterr()
    assert main(["bench", "report", "--no-progress"]) == 2
    assert "nothing to report" in capsys.readouterr().err


def test_the_paired_difference_is_in_the_paper_metric(runs: dict[str, Path]) -> None:
    rows = read_rows(runs["homes"] / "homes_trials.parquet")
    paired = paired_differences(rows, metric=discovery)["epl"]
    per_run = {}
    for strategy in ("wpl", "epl"):
        for home in ("ithor-01", "procthor-00"):
            mine = [
                discovery(r)
                for r in rows
                if (r.strategy, r.update_mode, r.home) == (strategy, "all", home)
            ]
            per_run[strategy, home] = sum(mine) / len(mine)
    diffs = [per_run["epl", h] - per_run["wpl", h] for h in ("ithor-01", "procthor-00")]
    assert (paired.n, paired.kind) == (2, "range")
    assert paired.mean == pytest.approx(sum(diffs) / 2)
    assert paired.low == pytest.approx(min(diffs)) and paired.high == pytest.approx(max(diffs))


def test_several_homes_runs_are_reported_as_one(runs: dict[str, Path], tmp_path: Path) -> None:
    # e.g. one bench homes run per schedule kind, each with its own scene count
    text = _report(runs, tmp_path, "--evaluation", str(runs["heldout"]))
    section = text.split("## Homes (not tuned on)")[1].split("\n## ")[0]
    assert f"--out {runs['homes']} " in section and f"--out {runs['heldout']} " in section
    assert "Homes (3): ithor-01, ithor-02, procthor-00." in section
    one = json.loads((runs["homes"] / "summary.json").read_text())["searches"]
    two = json.loads((runs["heldout"] / "summary.json").read_text())["searches"]
    assert f"{one + two} searches" in section
    # Both recorded the occluding camera: so does the merged section (its oracle note and the
    # failure causes depend on it).
    assert "This run recorded no camera" not in section


def test_runs_with_different_cameras_are_not_merged(
    runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    other = tmp_path / "geometric"
    shutil.copytree(runs["heldout"], other)
    summary = json.loads((other / "summary.json").read_text())
    (other / "summary.json").write_text(json.dumps({**summary, "camera": "geometric"}))
    argv = ["bench", "report", "--paper", str(runs["paper"]), "--evaluation", str(runs["homes"])]
    argv += ["--evaluation", str(other), "--out", str(tmp_path / "r.md")]
    assert main(argv) == 2
    assert "different cameras (geometric, occluding): report them apart" in capsys.readouterr().err
    assert not (tmp_path / "r.md").exists()


def test_a_run_without_a_camera_gets_no_computed_cause(runs: dict[str, Path]) -> None:
    # Its schedules were drawn before the visibility checks: today's draw is another scene.
    rows = read_rows(runs["homes"] / "homes_trials.parquet")
    failed = dataclasses.replace(rows[0], success=False)
    assert "not computed: the run predates" in failure_lines([failed], None)[-1]


def test_report_with_only_paper_writes_under_out(
    runs: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """By default the page and its plots go to out/report/, never over docs/; the homes section,
    like every other whose input is not given, says which command produces it."""
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "report", "--paper", str(runs["paper"])]) == 0
    text = (tmp_path / "out" / "report" / "results.md").read_text(encoding="utf-8")
    assert (tmp_path / "out" / "report" / "img" / "scene_graph_before_after.png").is_file()
    assert "![scene graph](img/scene_graph_before_after.png)" in text
    assert "## Homes (not tuned on)\n\nNot in this report: run `objsearch bench homes" in text
    assert text.count("Not in this report:") == 4
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_report_help_shows_its_defaults(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("COLUMNS", "400")  # no help line wrapped inside a word
    assert main(["bench", "report", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    for default in (
        "(default: out/bench-paper if it holds one;",
        "(out/report/results.md)",
        "(default: img/ beside --out)",
        "(default: results-rearrangement.md beside --out)",
    ):
        assert default in text, default


def test_the_html_report_renders_in_chromium(runs: dict[str, Path], tmp_path: Path) -> None:
    _report(runs, tmp_path, "--html")
    index = tmp_path / "docs" / "index.html"
    html = index.read_text(encoding="utf-8")
    assert "<img" not in html and "<script src" not in html  # every figure inline, as SVG
    with Browser() as browser:
        browser.open(index)
        drawn = browser.evaluate(IMAGES_RENDERED)
        # longterm, route, scene graph, the learning curves and the per-home bars
        assert drawn["svgs"] == 5 and drawn["bad"] == []
        tables = browser.evaluate("document.querySelectorAll('table.sortable').length")
        assert tables >= 5
        browser.evaluate("window.scrollTo(0, document.querySelector('figure').offsetTop)")
        check_screenshot(browser.screenshot(tmp_path / "results.png"), 1280, 900)
        assert browser.errors == []
