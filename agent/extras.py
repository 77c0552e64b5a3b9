"""Optional extras: what a command needs beyond the base install, checked before it is used.

The wheel's own dependencies run every command but the one that fuses camera views into a
semantic map, ``objsearch map build`` (and its ``--model`` detector): that needs torch, the
``torch`` extra, kept out of the base install because an unpinned torch pulls gigabytes of CUDA
wheels a robot without a GPU never uses (README, "Install"). :func:`require_torch` is called
before the first ``import torch``, so a missing extra is an error that names it and the command
that installs it, not a traceback.
"""

from __future__ import annotations

import importlib.util
from typing import Final

from objsearch.agent.errors import ObjsearchError

#: The CPU build of torch and the extra in one command (the CUDA build works as well where wanted).
TORCH_INSTALL: Final = (
    "pip install 'objsearch[torch]' --extra-index-url https://download.pytorch.org/whl/cpu"
)


class MissingExtraError(ObjsearchError):
    """A command needs an optional extra that is not installed."""


def require(module: str, *, extra: str, purpose: str, install: str) -> None:
    """Raise :class:`MissingExtraError` naming ``extra`` if ``module`` cannot be imported."""
    if importlib.util.find_spec(module) is None:
        raise MissingExtraError(
            f"{purpose} needs {module}, which is not installed (the optional extra "
            f"'objsearch[{extra}]'): {install}"
        )


def require_torch(purpose: str) -> None:
    require("torch", extra="torch", purpose=purpose, install=TORCH_INSTALL)
