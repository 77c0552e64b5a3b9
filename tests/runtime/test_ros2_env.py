"""rclpy only where it is used (runtime/ros2_env.py): the setup leaves a plain Python process of
the venv starting once, without the editable hook's imports, and a ``--transport ros2`` command
sets the ROS environment for itself."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

from objsearch.runtime import ros2_env

from .runtime_fixtures import next_domain

PROBE = (
    "import os, sys; "
    "print(os.environ.get('_ROS_WHEELS_BOOTSTRAP_COMPLETE'), 'pathlib' in sys.modules)"
)


def plain_env() -> dict[str, str]:
    """As a shell that never sourced ROS starts a process."""
    drop = {"LD_LIBRARY_PATH", ros2_env.BOOTSTRAPPED, "PYTHONPATH"}
    return {k: v for k, v in os.environ.items() if k not in drop}


def test_the_setup_removes_the_re_exec_hook_and_defers_the_editable_hook(tmp_path: Path) -> None:
    """A venv of this interpreter with the ROS 2 wheels' bootstrapper and objsearch's editable
    install copied in, before and after ``python -m objsearch.runtime.ros2_env --setup``."""
    venv = tmp_path / "venv"
    base = getattr(sys, "_base_executable", sys.executable)
    subprocess.run([base, "-m", "venv", "--without-pip", str(venv)], check=True)
    ours, site = ros2_env.site_packages(), ros2_env.site_packages(venv)
    # The two hooks as pip installs them (this venv's own may have been set up already).
    shutil.copytree(ours / "ros_wheels_bootstrapper", site / "ros_wheels_bootstrapper")
    (site / ros2_env.HOOK).write_text("import ros_wheels_bootstrapper\n")
    (finder,) = ours.glob("__editable___objsearch_*_finder.py")
    shutil.copy(finder, site / finder.name)
    module = finder.name.removesuffix(".py")
    (site / "__editable__.objsearch-0.pth").write_text(f"import {module}; {module}.install()\n")
    python = str(venv / "bin" / "python")

    def probe() -> str:
        done = subprocess.run(
            [python, "-c", PROBE], env=plain_env(), capture_output=True, text=True, check=True
        )
        return done.stdout.strip()

    # Before: every interpreter starts twice (the hook's guard is set by its re-exec), and the
    # editable hook imports pathlib at every start.
    assert probe() == "1 True"
    setup = subprocess.run(
        [python, "-m", "objsearch.runtime.ros2_env", "--setup"],
        env=plain_env(),
        capture_output=True,
        text=True,
    )
    assert setup.returncode == 0, setup.stderr
    assert "removed the ROS 2 wheels' re-exec hook" in setup.stderr
    assert "made objsearch's editable import hook lazy" in setup.stderr
    assert probe() == "None False"
    # objsearch is still importable through the deferred hook (ros2_env imports nothing of ours).
    found = subprocess.run(
        [python, "-c", "import objsearch.runtime.ros2_env as e; print(e.__file__)"],
        env=plain_env(),
        capture_output=True,
        text=True,
        check=True,
    )
    assert found.stdout.strip().endswith("runtime/ros2_env.py")
    again = subprocess.run(
        [python, "-m", "objsearch.runtime.ros2_env", "--setup"],
        env=plain_env(),
        capture_output=True,
        text=True,
        check=True,
    )
    assert again.stderr == ""  # nothing left to do


def test_a_ros2_command_sets_its_own_environment() -> None:
    """``agent where --transport ros2`` started without the libraries on the path (as after the
    setup) restarts itself with them: it reaches the graph and says nobody answered, rather
    than failing to load rclpy."""
    env = {**plain_env(), ros2_env.BOOTSTRAPPED: "1"}  # a hook still in the venv stays inert
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "objsearch.cli",
            "agent",
            "where",
            "Apple",
            "--transport",
            "ros2",
            "--domain-id",
            str(next_domain()),
            "--timeout",
            "1",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 2, done.stderr
    assert "objsearch: error: no answer to where Apple" in done.stderr, done.stderr
    # The same order in every process (the bootstrapper's came from a set).
    dirs = ros2_env.library_dirs()
    assert dirs == [*sorted(dirs[:-1]), str(Path(sys.prefix) / "lib")]
    assert ros2_env.library_path({}) == os.pathsep.join(dirs)
    assert ros2_env.library_path({"LD_LIBRARY_PATH": f"/x{os.pathsep}{dirs[0]}"}).endswith(
        f"{os.pathsep}/x"
    )
