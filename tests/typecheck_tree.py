"""Lay the package out for mypy the way it installs, generated from pyproject's package-dir.

``[tool.setuptools.package-dir]`` maps ``objsearch.agent`` to ``agent/`` and so on; the editable
install's import hook does this at run time, but mypy cannot follow it. ``make typecheck`` runs
``python tests/typecheck_tree.py OUT`` and points ``MYPYPATH`` at ``OUT``: a tree of symlinks made
from the same table setuptools reads, so it cannot drift from what a wheel holds.
"""

from __future__ import annotations

import shutil
import sys
import tomllib
from collections.abc import Mapping
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def package_dirs(pyproject: Path = REPO / "pyproject.toml") -> dict[str, str]:
    doc = tomllib.loads(pyproject.read_text(encoding="utf-8"))
    mapping: dict[str, str] = doc["tool"]["setuptools"]["package-dir"]
    return mapping


def build_tree(out: Path, mapping: Mapping[str, str], root: Path = REPO) -> None:
    """Symlink each mapped package to its folder under ``out``; a package with mapped
    sub-packages becomes a real folder of links to its files, so the sub-packages fit in."""
    shutil.rmtree(out, ignore_errors=True)
    for name in sorted(mapping):  # a package sorts before its sub-packages
        source = (root / mapping[name]).resolve()
        dest = out.joinpath(*name.split("."))
        nested = {n[len(name) + 1 :].split(".")[0] for n in mapping if n.startswith(name + ".")}
        if not nested:
            dest.parent.mkdir(parents=True, exist_ok=True)
            dest.symlink_to(source, target_is_directory=True)
            continue
        dest.mkdir(parents=True, exist_ok=True)
        for child in source.iterdir():
            if child.name not in nested and child.name != "__pycache__":
                (dest / child.name).symlink_to(child)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python tests/typecheck_tree.py OUT", file=sys.stderr)
        return 2
    build_tree(Path(args[0]), package_dirs())
    return 0


if __name__ == "__main__":
    sys.exit(main())
