"""What the project's venv adds to every Python process: CPU time of ``python -c pass`` in this
venv against a plain venv of the same interpreter, made for the run, both measured in the same
run.

    python benchmarks/python_startup.py [--reps 21]

Each interpreter runs ``-c pass`` ``--reps`` times, the two interleaved (so a busy moment
weighs on both), with this process's environment less ``LD_LIBRARY_PATH`` and the ROS 2 wheels'
guard variable (as a shell that never sourced ROS starts it); CPU time is the child's user +
system time (``resource.getrusage(RUSAGE_CHILDREN)``). Medians and the ratio are printed.
Target (issue 44): at most 1.5x the plain venv. The ROS 2 wheels' ``.pth`` hook re-executed
every interpreter (about 2x), and setuptools' editable import hook imports pathlib and re at
every start; ``make`` removes the first and makes the second lazy
(``python -m objsearch.runtime.ros2_env --setup``). The line after the ratio says whether each
is present here.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path

TARGET = 1.5


def cpu_seconds(argv: Sequence[str], env: Mapping[str, str]) -> float:
    """User + system CPU time of one run of ``argv`` (which must succeed)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(argv, check=True, env=dict(env))
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--reps", type=int, default=21, help="runs of each interpreter (21)")
    args = parser.parse_args()
    if args.reps < 1:
        parser.error("--reps must be at least 1")
    from objsearch.runtime import ros2_env

    env = {
        k: v
        for k, v in os.environ.items()
        if k not in {"LD_LIBRARY_PATH", ros2_env.BOOTSTRAPPED, "PYTHONPATH"}
    }
    base = getattr(sys, "_base_executable", sys.executable)
    venv_python = Path(sys.prefix) / "bin" / "python"
    with tempfile.TemporaryDirectory(prefix="objsearch-pystart-") as tmp:
        plain = Path(tmp) / "plain"
        subprocess.run([base, "-m", "venv", "--without-pip", str(plain)], check=True)
        runs: dict[str, list[float]] = {"plain venv": [], "project venv": []}
        commands = {
            "plain venv": [str(plain / "bin" / "python"), "-c", "pass"],
            "project venv": [str(venv_python), "-c", "pass"],
        }
        for argv in commands.values():
            cpu_seconds(argv, env)  # warm the page cache and bytecode once, unmeasured
        for _ in range(args.reps):
            for name, argv in commands.items():
                runs[name].append(cpu_seconds(argv, env))
    medians = {name: statistics.median(times) for name, times in runs.items()}
    print(f"python -c pass, {args.reps} runs each, CPU seconds (user + system), median [min, max]")
    for name, times in runs.items():
        print(
            f"  {name:13} {medians[name]:.4f} [{min(times):.4f}, {max(times):.4f}]  {commands[name][0]}"
        )
    ratio = medians["project venv"] / medians["plain venv"]
    verdict = "met" if ratio <= TARGET else "NOT met"
    print(f"ratio project / plain: {ratio:.2f} (target <= {TARGET}: {verdict})")
    site = ros2_env.site_packages()
    hook = (site / ros2_env.HOOK).is_file()
    editable = sorted(site.glob("__editable__.objsearch-*.pth"))
    lazy = all("_ObjsearchLazyFinder" in p.read_text(encoding="utf-8") for p in editable)
    print(
        f"ROS 2 wheels' re-exec hook: {'present' if hook else 'absent'}; "
        f"editable import hook: {'lazy' if lazy else 'eager'} ({len(editable)} file(s))"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
