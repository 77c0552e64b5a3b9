"""The package as a robot gets it: built as a wheel, installed in a fresh venv, run from elsewhere.

Most tests share a venv that reuses the project's dependencies (a ``.pth`` line naming this
interpreter's site-packages) and installs only the wheel, offline, so they take seconds. That
``.pth`` line adds the folder to ``sys.path`` without running the editable install's import hook,
so ``objsearch`` can only come from the wheel. One slow test installs the wheel as the README tells
a robot to, into an empty venv with pip resolving every dependency (pip's cache and this machine's
pip configuration; about 1-1.5 minutes here, most of it unpacking pyarrow, polars, DuckDB, OpenCV),
and runs a search there without torch. It passes ``--no-compile``: pip's byte-compiling of every
installed module was a third of the install (76 -> 47 s and 99 -> 65 s, two rounds at load 6-10;
the whole test 29.9 and 25.9 -> 23.5 and 22.3 s at load 2-3), what the search imports is compiled
when it is imported, and whether pip compiles decides nothing the test checks (its failures are
only warnings).
"""

from __future__ import annotations

import ast
import json
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import venv
import zipfile
from dataclasses import dataclass
from email.parser import Parser
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


#: What only the tests and benchmarks use: the harness folder and what only the dev extra installs.
DEV_ONLY_IMPORTS = frozenset({"devtools", "tests", "moto", "werkzeug", "pytest", "hypothesis"})
#: The harnesses, fuzzers and batteries (devtools/), by the names they had in the package.
HARNESS = re.compile(r"(^objsearch/testing/|battery|fuzz|flood|crashtest|killtest|s3server)")


def test_the_wheel_holds_no_harness_fuzzer_or_battery(installed: Installed) -> None:
    names = zipfile.ZipFile(installed.wheel).namelist()
    assert [n for n in names if n.endswith(".py") and HARNESS.search(n)] == []


def _imported(source: str) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found.add(node.module.split(".")[0])
    return found


def test_the_wheel_imports_nothing_only_the_dev_extra_installs(installed: Installed) -> None:
    wheel = zipfile.ZipFile(installed.wheel)
    dev = {
        name: sorted(_imported(wheel.read(name).decode("utf-8")) & DEV_ONLY_IMPORTS)
        for name in wheel.namelist()
        if name.endswith(".py")
    }
    assert {name: found for name, found in dev.items() if found} == {}


def _requires(wheel: Path) -> list[str]:
    archive = zipfile.ZipFile(wheel)
    [meta] = [n for n in archive.namelist() if n.endswith(".dist-info/METADATA")]
    return Parser().parsestr(archive.read(meta).decode("utf-8")).get_all("Requires-Dist") or []


def test_torch_is_an_extra_not_a_dependency(installed: Installed) -> None:
    """Unpinned, a plain ``pip install`` of the wheel took the newest torch and 18 nvidia
    packages (~3 GB); only ``objsearch map build`` needs torch."""
    requires = _requires(installed.wheel)
    base = [r for r in requires if "extra ==" not in r]
    assert [r for r in base if re.match(r"(torch|nvidia)", r)] == []
    assert any(re.match(r'torch\b.*extra == "torch"', r) for r in requires), requires


def test_the_readme_gives_the_robots_install_command(installed: Installed) -> None:
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    assert f"pip install {installed.wheel.name}\n" in readme
    assert f"pip install '{installed.wheel.name}[torch]' --extra-index-url" in readme


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


@pytest.mark.slow
def test_a_robot_installs_the_wheel_with_one_command_and_searches(
    installed: Installed, tmp_path: Path
) -> None:
    """``pip install WHEEL`` (README, "Install") into an empty venv: every dependency resolved by
    pip, no torch and no CUDA; a search runs, and ``map build`` names the extra it needs. (With
    ``--no-compile``: see the module's docstring.)"""
    robot = tmp_path / "robot"
    venv.create(robot, with_pip=True)
    pip = [str(robot / "bin" / "python"), "-m", "pip", "--disable-pip-version-check"]
    _check([*pip, "install", "--quiet", "--no-compile", str(installed.wheel)], env=installed.env)
    listed = subprocess.run(
        [*pip, "list", "--format", "json"], capture_output=True, text=True, check=True
    ).stdout
    names = {d["name"].lower() for d in json.loads(listed)}
    assert "objsearch" in names
    assert sorted(n for n in names if n == "torch" or n.startswith("nvidia")) == []
    bin_ = robot / "bin" / "objsearch"
    search = subprocess.run(
        [str(bin_), "search", "Apple", "--start", "kitchen-1", "--format", "json"],
        cwd=installed.elsewhere,
        env=installed.env,
        capture_output=True,
        text=True,
        check=False,
    )
    assert search.returncode == 0, search.stderr
    assert json.loads(search.stdout)["found"].startswith("kitchen/Apple")
    build = subprocess.run(
        [str(bin_), "map", "build", "--home", "paper"],
        cwd=installed.elsewhere,
        env=installed.env,
        capture_output=True,
        text=True,
        check=False,
    )
    assert build.returncode == 2, build.stderr
    assert "objsearch: error: objsearch map build needs torch" in build.stderr
    assert "'objsearch[torch]'" in build.stderr
    assert "Traceback" not in build.stderr
