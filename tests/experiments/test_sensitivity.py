"""bench sensitivity: a grid of detectors, each cell a bench homes run beside the reference that
sees with the same detector; the table (text, JSON, Markdown) and the plot."""

from __future__ import annotations

import contextlib
import io
import json
import math
import shlex
from pathlib import Path
from typing import Any

import pytest

from objsearch.cli import build_parser, main
from objsearch.experiments.calibration import ece
from objsearch.experiments.homes import run_homes
from objsearch.experiments.runner import read_rows
from objsearch.experiments.sensitivity import Cell, cell_jobs, cell_perception, grid

#: The tiny sweep: one development home, one seed, one scene, one start, a 2 × 2 grid.
HOME = "ithor-02"
STRATEGIES = ("global-belief+cover", "wpl+cover")
REFERENCE = "dist-oracle-global+cover"


@pytest.fixture(scope="module")
def sweep(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any], str, str]:
    out = tmp_path_factory.mktemp("sensitivity")
    argv = [
        "bench", "sensitivity", "--out", str(out), "--homes", HOME, "--seeds", "1",
        "--scenes-per-schedule", "1", "--starts-per-scene", "1", "--recall-scales", "1,0.5",
        "--fp-rates", "0", "--fp-rates", "0.5", "--workers", "1",
    ]  # fmt: skip
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        assert main(argv) == 0
    summary = json.loads((out / "sensitivity.json").read_text(encoding="utf-8"))
    return out, summary, stdout.getvalue(), stderr.getvalue()


@pytest.mark.slow
def test_the_sweep_writes_the_table_and_the_plot(
    sweep: tuple[Path, dict[str, Any], str, str],
) -> None:
    out, summary, stdout, stderr = sweep
    for name in ("sensitivity.txt", "sensitivity.md", "sensitivity.svg", "sensitivity.pdf"):
        assert (out / name).stat().st_size > 0, name
    assert (out / "sensitivity.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert summary["plot"] == ["sensitivity.png", "sensitivity.svg", "sensitivity.pdf"]
    cells = [(c["recall_scale"], c["fp_per_image"]) for c in summary["cells"]]
    assert cells == [(1.0, 0.0), (1.0, 0.5), (0.5, 0.0), (0.5, 0.5)]
    # A progress line per cell, into a pipe too.
    assert stderr.count("bench sensitivity: cell ") == 4
    assert "cell 4/4 recall ×0.5, 0.5 FP/image" in stderr
    table = (out / "sensitivity.txt").read_text(encoding="utf-8")
    assert table in stdout
    markdown = (out / "sensitivity.md").read_text(encoding="utf-8")
    assert summary["command"] in markdown
    # The recorded command runs the same sweep.
    again = build_parser().parse_args(shlex.split(summary["command"])[1:])
    assert (again.recall_scales, again.fp_rates, again.homes) == (
        [1.0, 0.5],
        [0.0, 0.5],
        ["ithor-02"],
    )
    assert (again.scenes_per_schedule, again.starts_per_scene, again.perception) == (
        1,
        1,
        "perfect",
    )
    for cell in summary["cells"]:
        assert set(cell["strategies"]) == {*STRATEGIES, REFERENCE}
        folder = out / "cells" / Cell(cell["recall_scale"], cell["fp_per_image"]).name
        assert (folder / "homes_trials.parquet").is_file()
        for name in STRATEGIES:
            m = cell["strategies"][name]
            assert m["searches"] > 0 and 0.0 <= m["success_rate"] <= 1.0
            assert 0.0 <= m["false_found_rate"] <= 1.0 - m["success_rate"] + 1e-9
            assert m["reference"] == REFERENCE and 0.0 < m["reference_ratio"] < 20.0
            assert 0 < m["scored"] <= m["searches"]
            assert 0.0 <= m["ece"] <= 1.0 and 0.0 <= m["brier"] <= 2.0
            # Each strategy's row of each cell is in the text and in the Markdown block.
            row = f"| {cell['recall_scale']:g} | {cell['fp_per_image']:g} | {name} | {m['searches']} |"
            assert row in markdown
        assert cell["strategies"][REFERENCE]["reference_ratio"] is None
    # Only the perfect cell records no detector; the others the grid's numbers.
    assert summary["cells"][0]["perception"] == {"preset": "perfect"}
    noisy = summary["cells"][3]["perception"]
    assert (noisy["recall_scale"], noisy["fp_per_image"]) == (0.5, 0.5)


@pytest.mark.slow
def test_recall_one_and_no_false_positives_is_the_perfect_run(
    sweep: tuple[Path, dict[str, Any], str, str], tmp_path: Path
) -> None:
    _, summary, _, _ = sweep
    perfect = run_homes(
        tmp_path,
        homes=[HOME],
        strategies=[*STRATEGIES, REFERENCE],
        seeds=1,
        scenes=1,
        workers=1,
        progress=False,
        schedules=("habit",),
        starts_per_search=1,
    )
    # bench homes also runs wpl without learning (wpl+cover/none): not part of the grid.
    rows = [r for r in read_rows(tmp_path / "homes_trials.parquet") if r.update_mode == "all"]
    cell = summary["cells"][0]["strategies"]
    for name in STRATEGIES:
        theirs = perfect["overall"][name]
        mine = cell[name]
        assert mine["searches"] == theirs["n"]
        assert mine["success_rate"] == theirs["success_rate"]
        assert mine["mean_path_length"] == pytest.approx(theirs["mean_path_length"], abs=1e-9)
        assert mine["reference_ratio"] == pytest.approx(theirs["reference_ratio"], abs=1e-9)
        scored = [r for r in rows if r.strategy == name and r.belief_top_p is not None]
        pairs = [(float(r.belief_top_p or 0.0), bool(r.belief_top_hit)) for r in scored]
        assert mine["ece"] == pytest.approx(ece(pairs), abs=1e-12)
        brier = math.fsum(float(r.belief_brier or 0.0) for r in scored) / len(scored)
        assert mine["brier"] == pytest.approx(brier, abs=1e-12)
    # A worse detector changes the figures (the cells are not one run printed four times).
    worst = summary["cells"][3]["strategies"]["global-belief+cover"]
    assert worst["mean_path_length"] != cell["global-belief+cover"]["mean_path_length"]


def test_the_grid_and_its_jobs() -> None:
    assert grid([1.0, 0.5, 1.0], [0.0, 0.25]) == [
        Cell(1.0, 0.0), Cell(1.0, 0.25), Cell(0.5, 0.0), Cell(0.5, 0.25),
    ]  # fmt: skip
    assert cell_perception("perfect", Cell(1.0, 0.0)) is None
    realistic = cell_perception("realistic", Cell(1.0, 0.0))
    assert realistic is not None and realistic["recall_small"] < 1.0
    assert realistic["fp_per_image"] == 0.0 and realistic["confusion"] == 0.05
    jobs = cell_jobs(
        Cell(1.0, 0.0), base="perfect", homes=["ithor-02"], strategies=list(STRATEGIES), seeds=2,
        scenes=3, schedules=("habit",), starts_per_search=1,
    )  # fmt: skip
    # The reference in the perfect cell too; no wpl/none run (bench homes adds one).
    assert sorted({j.strategy for j in jobs}) == sorted({*STRATEGIES, REFERENCE})
    assert {j.update_mode for j in jobs} == {"all"} and len(jobs) == 3 * 2
    assert all(j.perception is None for j in jobs)
    harsh = cell_jobs(
        Cell(0.5, 1.0), base="perfect", homes=["ithor-02"], strategies=list(STRATEGIES), seeds=1,
        scenes=1, schedules=("habit",), starts_per_search=1,
    )  # fmt: skip
    params = json.loads(harsh[0].perception or "{}")
    assert (params["recall_scale"], params["fp_per_image"], params["confusion"]) == (0.5, 1.0, 0.0)


def test_a_cell_relooks_as_its_preset_does_unless_told() -> None:
    """The modelled presets look again at a stop that missed; the perfect base does not, even in
    a cell whose recall makes it miss, unless ``--relook`` says so (and ``off`` is then left out
    of the run spec, as every run spec that names no relook)."""
    assert cell_perception("realistic", Cell(1.0, 0.1))["relook"] == "likeliest"  # type: ignore[index]
    assert "relook" not in (cell_perception("perfect", Cell(0.5, 0.1)) or {})
    on = cell_perception("perfect", Cell(0.5, 0.1), "likeliest")
    assert on is not None and on["relook"] == "likeliest"
    off = cell_perception("realistic", Cell(1.0, 0.1), "off")
    assert off is not None and "relook" not in off
    assert cell_perception("perfect", Cell(1.0, 0.0), "likeliest") is None
    jobs = cell_jobs(
        Cell(0.5, 0.0), base="perfect", homes=["ithor-02"], strategies=list(STRATEGIES), seeds=1,
        scenes=1, schedules=("habit",), starts_per_search=1, relook="likeliest",
    )  # fmt: skip
    assert all(json.loads(j.perception or "{}")["relook"] == "likeliest" for j in jobs)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--recall-scales", "1,1.5"], "argument --recall-scales: must be between 0 and 1, not 1.5"),
        (["--recall-scales", "nan"], "argument --recall-scales: must be a finite number"),
        (["--fp-rates", "-0.5"], "argument --fp-rates: must be between 0 and 20, not -0.5"),
        (["--fp-rates", "often"], "argument --fp-rates: expected a number"),
        (["--fp-rates", ","], "argument --fp-rates: expected numbers between 0 and 20"),
        (["--perception", "blurry"], "argument --perception: invalid choice"),
        (["--relook", "sometimes"], "argument --relook: invalid choice"),
        (["--seeds", "0"], "argument --seeds: must be between 1 and 1000"),
        (["--homes", "nowhere"], "unknown home(s) nowhere"),
        (["--homes", "ithor-02", "--strategies", "magic"], "unknown strategy 'magic'"),
        (["--homes", "ithor-02", "--schedules", "weekly"], "unknown schedule kind(s) weekly"),
    ],
)  # fmt: skip
def test_bad_options_are_clear_errors(
    argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    try:
        code = main(["bench", "sensitivity", "--out", str(out), "--workers", "1", *argv])
    except SystemExit as exit_:
        code = int(exit_.code or 0)
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("objsearch: error: ") and message in err
    assert not (out / "sensitivity.json").exists()
