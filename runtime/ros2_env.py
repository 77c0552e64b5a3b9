"""The environment rclpy needs, given only to the processes that use it.

The ROS 2 wheels' libraries live in ``site-packages/ros_*.libs`` and the environment's ``lib/``;
rclpy's C extension finds them through ``LD_LIBRARY_PATH``, which the dynamic linker reads once,
when a process starts. The wheels bring ``ros-wheels-bootstrapper``, a ``.pth`` file that sets it
by re-executing *every* Python interpreter of the environment (``python -c pass`` then costs
twice its CPU, and the variable comes out in a set's order, a random one per process). Here
instead:

* the setup (``make``) removes that hook (:func:`remove_hook`) and makes the editable install's
  import hook lazy (:func:`lazy_editable_hook`), so a Python process that uses neither costs
  what a plain interpreter does;
* a command that opens the ``ros2`` transport re-executes itself once with the environment
  set (:func:`reexec`, called by ``objsearch.cli_runtime``), and the test suite does the same
  for pytest (``tests/conftest.py``);
* ``python -m objsearch.runtime.ros2_env CMD …`` runs any command in it (``--print``: the
  ``export`` line for a shell), as ``source setup.bash`` would.

The path is always the same order: the wheels' library folders sorted, then ``lib/``, then
whatever the variable held before (an entry already listed is not repeated). Only ``os``,
``sys`` and ``sysconfig`` are imported: this runs at a command's start.
"""

from __future__ import annotations

import os
import sys
import sysconfig
from collections.abc import Mapping, Sequence
from pathlib import Path

#: The bootstrapper's guard: set, its hook does nothing (a venv that still has it).
BOOTSTRAPPED = "_ROS_WHEELS_BOOTSTRAP_COMPLETE"
HOOK = "ros_wheels_bootstrapper.pth"


def site_packages(prefix: Path | None = None) -> Path:
    base = str(prefix or sys.prefix)
    return Path(sysconfig.get_paths(vars={"base": base, "platbase": base})["purelib"])


def library_dirs(prefix: Path | None = None) -> list[str]:
    """The folders of the ROS 2 wheels' libraries, in a fixed order (none without the wheels)."""
    root = prefix or Path(sys.prefix)
    site = site_packages(root)
    wheels = sorted(str(p) for p in site.glob("ros_*.libs") if p.is_dir()) if site.is_dir() else []
    return [*wheels, str(root / "lib")] if wheels else []


def library_path(env: Mapping[str, str] | None = None, prefix: Path | None = None) -> str:
    env = os.environ if env is None else env
    dirs = library_dirs(prefix)
    before = [p for p in env.get("LD_LIBRARY_PATH", "").split(os.pathsep) if p and p not in dirs]
    return os.pathsep.join([*dirs, *before])


def ready(env: Mapping[str, str] | None = None, prefix: Path | None = None) -> bool:
    """Whether ``env`` (this process's, by default) already names every library folder."""
    env = os.environ if env is None else env
    have = set(env.get("LD_LIBRARY_PATH", "").split(os.pathsep))
    return all(d in have for d in library_dirs(prefix))


def environment(env: Mapping[str, str] | None = None, prefix: Path | None = None) -> dict[str, str]:
    """A copy of ``env`` in which rclpy can be imported."""
    out = dict(os.environ if env is None else env)
    path = library_path(out, prefix)
    if path:
        out["LD_LIBRARY_PATH"] = path
    out[BOOTSTRAPPED] = "1"
    return out


def reexec(argv: Sequence[str] | None = None) -> None:
    """Start this process again with the ROS environment, unless it has it (then return). The
    caller must have done nothing that a restart would repeat or lose."""
    if ready() or not library_dirs():
        return
    args = list(sys.orig_argv if argv is None else argv)
    sys.stdout.flush()
    sys.stderr.flush()
    os.execve(sys.executable, args, environment())


def remove_hook(prefix: Path | None = None) -> Path | None:
    """Delete the bootstrapper's ``.pth`` (the path, if there was one)."""
    hook = site_packages(prefix) / HOOK
    if hook.is_file():
        hook.unlink()
        return hook
    return None


#: What an editable install's ``.pth`` holds after :func:`lazy_editable_hook`: a finder that
#: imports setuptools' real one (pathlib, re, importlib.util: most of a bare start's cost) the
#: first time ``objsearch`` itself is imported, and hands it that import.
_LAZY = "import sys; exec({code!r})\n"  # a .pth runs only lines that start with "import"
_LAZY_CODE = """class _ObjsearchLazyFinder:
    @classmethod
    def find_spec(cls, fullname, path=None, target=None):
        if fullname.partition(".")[0] != "objsearch":
            return None
        real = __import__({module!r})  # a string: a name in a class body would be mangled
        sys.meta_path[:] = [f for f in sys.meta_path if f is not cls]
        real.install()
        return real._EditableFinder.find_spec(fullname, path, target)
sys.meta_path.append(_ObjsearchLazyFinder)
"""


def lazy_editable_hook(prefix: Path | None = None) -> Path | None:
    """Rewrite objsearch's editable ``.pth`` (``import X; X.install()``) to install its finder
    on first use; the path rewritten, or None (no editable install, or already lazy)."""
    for pth in sorted(site_packages(prefix).glob("__editable__.objsearch-*.pth")):
        text = pth.read_text(encoding="utf-8").strip()
        head, sep, tail = text.partition(";")
        module = head.removeprefix("import ").strip()
        if not sep or not head.startswith("import ") or tail.strip() != f"{module}.install()":
            continue  # not setuptools' form (already lazy, or another layout): left alone
        pth.write_text(_LAZY.format(code=_LAZY_CODE.format(module=module)), encoding="utf-8")
        return pth
    return None


def main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    usage = "usage: python -m objsearch.runtime.ros2_env [--print | --setup | [--] CMD [ARG ...]]"
    if not args or args[0] in {"-h", "--help"}:
        print(
            usage + "\n\nRuns CMD with the environment rclpy needs; --print shows it as a "
            "shell export; --setup removes the ROS wheels' re-exec hook from this environment "
            "and makes the editable install's import hook lazy (make does it)."
        )
        return 0 if args else 2
    if args[0] == "--print":
        print(f"export LD_LIBRARY_PATH={library_path()!s}")
        return 0
    if args[0] == "--setup":
        for done, what in (
            (remove_hook(), "removed the ROS 2 wheels' re-exec hook"),
            (lazy_editable_hook(), "made objsearch's editable import hook lazy"),
        ):
            if done is not None:
                print(f"{what}: {done}", file=sys.stderr)
        return 0
    if args[0] == "--":
        args = args[1:]
    try:
        os.execvpe(args[0], args, environment())
    except OSError as exc:
        print(f"objsearch: error: cannot run {args[0]!r}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    return 0  # not reached


if __name__ == "__main__":
    raise SystemExit(main())
