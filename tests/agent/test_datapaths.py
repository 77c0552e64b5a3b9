"""Where the data is found, and where ``objsearch data build`` may write, from a checkout; and
that what is read of a home comes from the data folder named or set, in one process too."""

from __future__ import annotations

import json
import math
import shutil
import sysconfig
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from objsearch.agent.datapaths import (
    DATA_ENV,
    DataLocationError,
    build_output_dir,
    checkout_data_dir,
    data_dir,
    packaged_data_dir,
)
from objsearch.agent.detector_model import SIZES_FILE, class_sizes, preset
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.home import load_home
from objsearch.agent.session import DEFAULT_PRIOR, load_context
from objsearch.agent.strategies import RelationSpec
from objsearch.experiments.paper import table1_job
from objsearch.experiments.report_homes import failure_cause
from objsearch.experiments.runner import Row, run_jobs
from objsearch.sim.habit_schedule import habit_schedule
from objsearch.sim.models import SIM_MODELS
from objsearch.sim.placements import Schedule
from objsearch.sim.world import DEFAULT_CAMERA

REPO_DATA = Path(__file__).resolve().parents[2] / "data"


def test_the_packaged_data_is_the_checkouts_data_folder(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(DATA_ENV, raising=False)
    assert packaged_data_dir() == REPO_DATA
    assert data_dir() == REPO_DATA
    assert checkout_data_dir() == REPO_DATA
    assert (data_dir() / "homes" / "paper.json").is_file()


def test_objsearch_data_overrides(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    assert data_dir() == tmp_path
    assert build_output_dir(None) == tmp_path


def test_build_writes_to_the_checkout_by_default(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(DATA_ENV, raising=False)
    assert build_output_dir(None) == REPO_DATA
    assert build_output_dir("elsewhere") == Path("elsewhere")


def test_build_refuses_site_packages(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(DATA_ENV, raising=False)
    inside = Path(sysconfig.get_path("purelib")) / "objsearch" / "data"
    with pytest.raises(DataLocationError, match="refusing to write into the installed package"):
        build_output_dir(inside)
    monkeypatch.setenv(DATA_ENV, str(inside))  # a setting cannot smuggle it in either
    with pytest.raises(DataLocationError, match="refusing"):
        build_output_dir(None)


# One home id in two data folders, in one process: what is read of it comes from the folder
# named (``data``) or set (``$OBJSEARCH_DATA``). The caches of home contexts, rest points and
# failure causes were keyed by the home id alone and handed back the first folder's.

SHIFT_M = 0.013


def _changed_data(path: Path, file: str, change: Callable[[Any], Any]) -> Path:
    """A copy of the bundled data whose ``file`` is the bundled one's JSON passed through
    ``change``, written with another indentation (its bytes differ even if nothing else does)."""
    shutil.copytree(packaged_data_dir(), path, ignore=shutil.ignore_patterns("__pycache__"))
    doc = change(json.loads((path / file).read_text(encoding="utf-8")))
    (path / file).write_text(json.dumps(doc, indent=3), encoding="utf-8")
    return path


def test_a_home_context_is_each_data_folders(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv(DATA_ENV, raising=False)
    other = _changed_data(tmp_path / "other", "homes/paper.json", lambda doc: doc)
    bundled_digest = load_home(REPO_DATA / "homes" / "paper.json").digest
    other_digest = load_home(other / "homes" / "paper.json").digest
    assert bundled_digest != other_digest
    assert load_context("paper").home.digest == bundled_digest
    assert load_home("paper", other).digest == other_digest
    assert load_context("paper", other).home.digest == other_digest
    assert load_context("paper").home.digest == bundled_digest
    (tmp_path / "link").symlink_to(other)  # two spellings of one folder: one entry
    assert load_context("paper", tmp_path / "link") is load_context("paper", other)
    monkeypatch.setenv(DATA_ENV, str(other))
    assert load_context("paper").home.digest == other_digest


def _shifted_rest_points(doc: Any) -> Any:
    for room in doc["rooms"]:
        for s in room["statics"]:
            s["rest_points"] = [[p[0] + SHIFT_M, p[1], p[2]] for p in s.get("rest_points", ())]
    return doc


def _on_rest_points_of(folder: Path, schedule: Schedule) -> bool:
    """Whether every placement on a static with rest points lies on one of them in ``folder``'s
    file of the home."""
    doc = json.loads((folder / "homes" / f"{schedule.home}.json").read_text(encoding="utf-8"))
    rests = {s["id"]: s.get("rest_points", []) for r in doc["rooms"] for s in r["statics"]}
    placed = [p for scene in schedule.scenes.values() for p in scene.values()]
    checked = [p for p in placed if not p.inside and p.support is not None and rests[p.support]]
    assert checked
    return all(
        any(
            math.isclose(p.box.center[0], x, abs_tol=1e-9)
            and math.isclose(p.box.center[1], y, abs_tol=1e-9)
            for x, y, _ in rests[p.support]
        )
        for p in checked
    )


def test_a_habit_schedule_is_drawn_on_each_data_folders_rest_points(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv(DATA_ENV, raising=False)
    other = _changed_data(tmp_path / "other", "homes/ithor-01.json", _shifted_rest_points)
    bundled = habit_schedule(load_home("ithor-01"), 0, scenes=2)
    assert _on_rest_points_of(REPO_DATA, bundled)
    named = habit_schedule(load_home("ithor-01", other), 0, scenes=2, data=other)
    assert _on_rest_points_of(other, named)
    assert not _on_rest_points_of(REPO_DATA, named)
    monkeypatch.setenv(DATA_ENV, str(other))
    assert _on_rest_points_of(other, habit_schedule(load_home("ithor-01"), 0, scenes=2))


def test_a_failure_cause_is_each_data_folders(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The paper home's Table I scene: the other folder's scenario removes the Cup too."""
    monkeypatch.delenv(DATA_ENV, raising=False)
    cup = "kitchen/Cup|+00.90|+01.67|-01.61"

    def without_cup(doc: Any) -> Any:
        return {**doc, "removed": sorted([*doc["removed"], cup])}

    other = _changed_data(tmp_path / "other", "scenarios/table1.json", without_cup)
    failed = Row(
        "homes", "paper", "table1", "wpl", "all", 1, 0, "Cup", "x", False, 0.0, 0.0, "task-1"
    )
    bundled = failure_cause(failed, "geometric")
    assert bundled != "not placed in this scene"
    assert failure_cause(failed, "geometric", other) == "not placed in this scene"
    assert failure_cause(failed, "geometric") == bundled
    monkeypatch.setenv(DATA_ENV, str(other))
    assert failure_cause(failed, "geometric") == "not placed in this scene"


def _doubled_cup(doc: Any) -> Any:
    doc["sizes"]["Cup"] = [2 * v for v in doc["sizes"]["Cup"]]
    return doc


def test_the_class_sizes_are_each_data_folders(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The policy's class sizes were read once per process from whichever folder came first."""
    monkeypatch.delenv(DATA_ENV, raising=False)
    other = _changed_data(tmp_path / "other", SIZES_FILE, _doubled_cup)
    bundled = class_sizes()["Cup"]
    assert class_sizes(other)["Cup"] == tuple(2 * v for v in bundled)
    assert class_sizes()["Cup"] == bundled
    assert class_sizes(other)["Apple"] == class_sizes()["Apple"]
    monkeypatch.setenv(DATA_ENV, str(other))
    assert class_sizes()["Cup"] == tuple(2 * v for v in bundled)


def test_a_run_on_a_named_data_folder_reads_only_that_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A job naming its data folder (``bench table1``'s) runs with $OBJSEARCH_DATA naming a
    folder that holds nothing: its home, scene, prior, belief and, under a modelled detector,
    the class sizes all come from the folder it names."""
    nothing = tmp_path / "nothing"
    nothing.mkdir()
    monkeypatch.setenv(DATA_ENV, str(nothing))
    named = _changed_data(tmp_path / "named", SIZES_FILE, _doubled_cup)
    job = table1_job("paper", "wpl", 0, ("Cup",), DEFAULT_PRIOR, DEFAULT_CAMERA, named)
    realistic = json.dumps(preset("realistic").params())
    rows = run_jobs([replace(job, perception=realistic)], progress=False)
    assert len(rows) == len(load_home("paper", named).starts)


def test_a_reference_oracle_refuses_a_named_data_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The simulator's oracles read only $OBJSEARCH_DATA or the bundled data: on a job that
    names another folder they would silently read another folder's homes and schedules."""
    monkeypatch.delenv(DATA_ENV, raising=False)
    other = _changed_data(tmp_path / "other", "homes/paper.json", lambda doc: doc)
    oracle = RelationSpec("dist-oracle")
    with pytest.raises(ObjsearchError, match=f"run it with {DATA_ENV}={other}"):
        oracle.build(SIM_MODELS, data=other)
    job = table1_job("paper", "dist-oracle", 0, ("Cup",), DEFAULT_PRIOR, DEFAULT_CAMERA, other)
    with pytest.raises(ObjsearchError, match="dist-oracle relation model reads the data of"):
        run_jobs([job], progress=False)
    oracle.build(SIM_MODELS, data=REPO_DATA)  # the folder it reads
    monkeypatch.setenv(DATA_ENV, str(other))
    assert run_jobs([job], progress=False)  # set as the variable, it is the folder it reads
