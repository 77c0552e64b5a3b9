"""Where the project's derived data lives.

One setting decides it: ``$OBJSEARCH_DATA``, when set, names the data folder. Unset, the data is the
package's own ``objsearch.data``: the repository's ``data/`` folder, which an editable install maps
in place and a wheel ships as package data (``[tool.setuptools.package-data]``). A reader that
reads a named folder instead (``bench belief``: each output's homes from the folder it was run
on) passes it as ``data`` down to where the files are read, never setting the variable around
the call; the caches of what is read are keyed by the resolved folder (:func:`data_key`) and
the id, never by the id alone. Nothing here knows where a checkout is, except
:func:`build_output_dir`, which must not write into an installed package.
"""

from __future__ import annotations

import functools
import os
import site
import sysconfig
from importlib import resources
from pathlib import Path

from objsearch.agent.errors import ObjsearchError

DATA_ENV = "OBJSEARCH_DATA"
DATA_PACKAGE = "objsearch.data"


class DataLocationError(ObjsearchError):
    """The data folder cannot be found, or a build would write where it must not."""


def data_dir(data: Path | None = None) -> Path:
    """The derived-data folder: ``data`` when given (a caller that reads a named folder, as
    ``bench belief`` does each output's), else ``$OBJSEARCH_DATA`` if set, else the packaged
    ``objsearch.data``."""
    if data is not None:
        return data
    env = os.environ.get(DATA_ENV)
    return Path(env) if env else packaged_data_dir()


def data_key(data: Path | None = None) -> Path:
    """:func:`data_dir` resolved: what a cache of anything read from the data folder is keyed by,
    with the home id or file (a home id names one home per folder only, and two spellings of one
    folder are one key)."""
    return _resolved(data, os.environ.get(DATA_ENV))


@functools.cache
def _resolved(data: Path | None, env: str | None) -> Path:
    # Keyed by what decides the folder (``env``: $OBJSEARCH_DATA now), so a changed variable is a
    # new key; the caches call data_key per placement and slot, and resolving walks the disk.
    return data_dir(data).resolve()


def packaged_data_dir() -> Path:
    """The data that ships with the package (the checkout's ``data/`` in an editable install)."""
    root = resources.files(DATA_PACKAGE)
    # Wheels install as plain files; a zipped install would hand back a Traversable that is not a
    # folder on disk, and the loaders (DuckDB, json, glob) need one.
    if not isinstance(root, Path) or not root.is_dir():
        raise DataLocationError(
            f"the package's data ({DATA_PACKAGE}) is not a folder on disk ({root}); "
            f"set {DATA_ENV} to a data folder"
        )
    return root


def checkout_data_dir() -> Path | None:
    """The repository's ``data/`` when the package runs from a checkout, else ``None``."""
    try:
        data = packaged_data_dir()
    except DataLocationError:
        return None
    checkout = data.parent
    is_checkout = data.name == "data" and (checkout / "pyproject.toml").is_file()
    return data if is_checkout and not _inside_installation(data) else None


def build_output_dir(out: str | Path | None) -> Path:
    """Where ``objsearch data build`` writes: ``out``, else ``$OBJSEARCH_DATA``, else the
    checkout's ``data/``. Refuses an installed package's folder: an upgrade would overwrite it."""
    if out is not None:
        target = Path(out)
    elif env := os.environ.get(DATA_ENV):
        target = Path(env)
    else:
        found = checkout_data_dir()
        if found is None:
            raise DataLocationError(
                "no checkout to build into: this objsearch is installed as a package, whose data "
                f"is read-only; pass --out DIR and run with {DATA_ENV}=DIR"
            )
        target = found
    if _inside_installation(target):
        raise DataLocationError(
            f"refusing to write into the installed package ({target.resolve()}); pass --out DIR "
            f"outside site-packages and run with {DATA_ENV}=DIR"
        )
    return target


def _inside_installation(path: Path) -> bool:
    """Whether ``path`` lies in a site-packages folder or in the installed ``objsearch`` itself."""
    resolved = path.resolve()
    roots = {sysconfig.get_path("purelib"), sysconfig.get_path("platlib"), *site.getsitepackages()}
    if user := site.getusersitepackages():
        roots.add(user)
    # agent/ in a checkout; site-packages/objsearch/agent in a wheel, whose parent is objsearch
    package = Path(__file__).resolve().parent.parent
    if not (package / "pyproject.toml").is_file():  # a wheel, not a checkout
        roots.add(str(package))
    return any(resolved.is_relative_to(Path(r).resolve()) for r in roots if r)
