"""The engines ingest runs on: local processes and a real local Ray instance give the same lake."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from objsearch.cli import main
from objsearch.pipeline.bags.engines import (
    InlineEngine,
    ProcessEngine,
    RayEngine,
    TaskFailed,
    make_engine,
)
from objsearch.pipeline.bags.errors import BagConfigError
from objsearch.pipeline.bags.ingest import ingest
from objsearch.pipeline.bags.lake import FleetBagLake

from .bag_fixtures import Recorded


@pytest.fixture(scope="module")
def ray_local() -> Iterator[Any]:
    ray = pytest.importorskip(
        "ray", reason="Ray is not installed (pip install 'objsearch[fleet]'); Ray path untested"
    )
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


def _exit_worker(code: int) -> int:
    os._exit(code)  # a worker that dies without answering


def test_a_task_that_raises_or_dies_is_reported_not_raised() -> None:
    assert list(InlineEngine().run(int, ["7"])) == [(0, 7)]
    outcomes = dict(ProcessEngine(2).run(int, ["1", "x"]))
    assert outcomes[0] == 1
    assert isinstance(outcomes[1], TaskFailed) and "invalid literal" in outcomes[1].message
    [(_, died)] = ProcessEngine(1).run(_exit_worker, [3])
    assert isinstance(died, TaskFailed)


def test_ray_tasks_report_their_errors(ray_local: Any) -> None:
    outcomes = dict(RayEngine().run(int, ["1", "x"]))
    assert outcomes[0] == 1
    assert isinstance(outcomes[1], TaskFailed)
    assert outcomes[1].message.startswith("Ray task failed: ValueError: invalid literal")


def test_ray_ingest_equals_local_ingest(recorded: Recorded, ray_local: Any, tmp_path: Path) -> None:
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"\x00" * 100)
    bags = [junk, recorded.bag, tmp_path / "missing.bag"]
    local = ingest(bags, tmp_path / "local")
    on_ray = ingest(bags, tmp_path / "ray", engine=RayEngine())
    # A bad bag is reported on its own; the good one is committed whole, the same as locally.
    assert [r.error is None for r in on_ray] == [False, True, False]
    assert on_ray[0].error is not None and "not a ROS bag" in on_ray[0].error
    assert on_ray[2].error is not None and "no bag at" in on_ray[2].error
    assert on_ray[1].committed == local[1].committed > 0
    assert on_ray[1].report == local[1].report
    assert list(FleetBagLake(tmp_path / "ray").events()) == list(
        FleetBagLake(tmp_path / "local").events()
    )
    files = sorted(p.stat().st_mtime_ns for p in (tmp_path / "ray").rglob("*.parquet"))
    [again] = ingest([recorded.bag], tmp_path / "ray", engine=RayEngine())
    assert again.already and again.committed == 0 and again.error is None
    assert sorted(p.stat().st_mtime_ns for p in (tmp_path / "ray").rglob("*.parquet")) == files


def test_cli_engine_ray(
    recorded: Recorded, ray_local: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lake = str(tmp_path / "lake")
    args = ["ingest", str(recorded.bag), "--lake", lake, "--engine", "ray", "--no-progress"]
    assert main(args) == 0
    assert "committed" in capsys.readouterr().out
    assert main(args) == 0
    assert "already in the lake" in capsys.readouterr().out


def test_engine_ray_without_ray_says_what_to_install(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # what `import ray` sees without the extra
    bag = tmp_path / "any.bag"
    bag.write_bytes(b"")  # there, so the missing engine is the only thing wrong
    assert main(["ingest", str(bag), "--lake", str(tmp_path / "l"), "--engine", "ray"]) == 2
    assert "pip install 'objsearch[fleet]'" in capsys.readouterr().err
    assert not (tmp_path / "l").exists()


def test_engine_options_are_checked() -> None:
    with pytest.raises(BagConfigError, match="--address is for --engine ray"):
        make_engine("local", address="auto")
    with pytest.raises(BagConfigError, match="at least 1"):
        make_engine("local", workers=0)
    with pytest.raises(BagConfigError, match="unknown engine 'spark'"):
        make_engine("spark")
    assert isinstance(make_engine("local", workers=2), ProcessEngine)
