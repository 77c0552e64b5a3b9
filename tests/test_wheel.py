"""The package as a robot gets it: built as a wheel, installed in a fresh venv, run from elsewhere.

The venv reuses the project's dependencies (a ``.pth`` line naming this interpreter's
site-packages) and installs only the wheel, offline, so the whole module takes seconds. That
``.pth`` line adds the folder to ``sys.path`` without running the editable install's import hook,
so ``objsearch`` can only come from the wheel.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import venv
import zipfile
from dataclasses import dataclass
from pathlib import Path

import pytest

from objsearch.pipeline.homer import source_files as homer_files
from objsearch.pipeline.sourceinfo import HOMER

REPO = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.wheel


@dataclass(frozen=True)
class Installed:
    wheel: Path
    bin: Path
    site_packages: Path
    elsewhere: Path  # a working directory outside the checkout
    env: dict[str, str]

    def run(
        self, *args: str, env: dict[str, str] | None = None
    ) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [str(self.bin / "objsearch"), *args],
            cwd=self.elsewhere,
            env=env or self.env,
            capture_output=True,
            text=True,
            check=False,
        )


def _check(cmd: list[str], env: dict[str, str]) -> None:
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, f"{' '.join(cmd)} failed:\n{proc.stdout}\n{proc.stderr}"


def _build_inputs() -> list[str]:
    """What setuptools reads: pyproject, the readme and every folder of ``package-dir``."""
    doc = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
    folders = doc["tool"]["setuptools"]["package-dir"].values()
    return ["pyproject.toml", doc["project"]["readme"], *sorted(set(folders))]


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Installed:
    root = tmp_path_factory.mktemp("wheel")
    # Build from a copy, so setuptools' build/ and egg-info never touch the checkout and a stale
    # build/lib cannot carry a deleted module into the wheel.
    src = root / "src"
    src.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for name in _build_inputs():
        if (REPO / name).is_dir():
            shutil.copytree(REPO / name, src / name, ignore=ignore)
        else:
            shutil.copy2(REPO / name, src / name)
    env = {k: v for k, v in os.environ.items() if k not in ("OBJSEARCH_DATA", "PYTHONPATH")}
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check"]
    wheels = root / "wheels"
    _check(
        [
            *pip,
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "--no-index",
            "-w",
            str(wheels),
            str(src),
        ],
        env=env,
    )
    [wheel] = wheels.glob("objsearch-*.whl")

    venv.create(root / "venv", with_pip=False)
    python = root / "venv" / "bin" / "python"
    purelib = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    (Path(purelib) / "objsearch-deps.pth").write_text(sysconfig.get_path("purelib") + "\n")
    _check(
        [*pip, "--python", str(python), "install", "--no-deps", "--no-index", str(wheel)], env=env
    )
    elsewhere = root / "elsewhere"
    elsewhere.mkdir()
    return Installed(wheel, python.parent, Path(purelib), elsewhere, env)


def test_the_wheel_ships_the_data_and_no_tests(installed: Installed) -> None:
    names = set(zipfile.ZipFile(installed.wheel).namelist())
    shipped = {n.removeprefix("objsearch/data/") for n in names if n.startswith("objsearch/data/")}
    committed = {p.relative_to(REPO / "data").as_posix() for p in (REPO / "data").rglob("*.*")}
    assert shipped == {p for p in committed if "__pycache__" not in p}
    assert "PROVENANCE.md" in shipped  # the licence notices travel with the copies
    assert not [n for n in names if n.startswith("tests/") or "/golden/" in n]


def test_the_wheel_ships_the_vendored_sources_a_data_build_reads(installed: Installed) -> None:
    # sources/ is not in the shared data folder: without it, data build from a wheel would fail.
    names = set(zipfile.ZipFile(installed.wheel).namelist())
    wanted = {f"objsearch/sources/{p.as_posix()}" for p in [*homer_files(), HOMER.licence_file]}
    assert not wanted - names


def test_a_search_runs_from_the_installed_wheel(installed: Installed) -> None:
    proc = installed.run("search", "Apple", "--start", "kitchen-1", "--format", "json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["success"] is True
    assert out["found"].startswith("kitchen/Apple")
    where = subprocess.run(
        [
            str(installed.bin / "python"),
            "-c",
            "from objsearch.agent.datapaths import data_dir; print(data_dir())",
        ],
        cwd=installed.elsewhere,
        env=installed.env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    assert Path(where) == installed.site_packages / "objsearch" / "data"


def test_help_runs_from_the_installed_wheel(installed: Installed) -> None:
    proc = installed.run("--help")
    assert proc.returncode == 0, proc.stderr
    assert "search" in proc.stdout


def test_objsearch_data_overrides_the_shipped_data(installed: Installed, tmp_path: Path) -> None:
    env = {**installed.env, "OBJSEARCH_DATA": str(tmp_path)}
    proc = installed.run("search", "Apple", "--start", "kitchen-1", env=env)
    assert proc.returncode == 2
    assert f"no home 'paper' in {tmp_path / 'homes'}" in proc.stderr


def test_data_build_will_not_write_into_the_installed_package(installed: Installed) -> None:
    # An (empty) source folder: the option must name a folder, but it is never read, the target
    # is refused first.
    (installed.elsewhere / "shared-data").mkdir(exist_ok=True)
    source = str(installed.elsewhere / "shared-data")
    proc = installed.run("data", "build", "--source", source)
    assert proc.returncode == 2
    assert "no checkout to build into" in proc.stderr
    assert "--out DIR" in proc.stderr
    shipped = installed.site_packages / "objsearch" / "data"
    proc = installed.run("data", "build", "--source", source, "--out", str(shipped / "homes"))
    assert proc.returncode == 2
    assert "refusing to write into the installed package" in proc.stderr
