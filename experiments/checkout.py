"""Where a pinned public checkout an external benchmark runs (``bench dhs``, ``bench stot``) is:
``--source DIR``, else an environment variable. Each benchmark then checks the checkout's files
against its own pins."""

from __future__ import annotations

import os
from pathlib import Path

from objsearch.agent.errors import ObjsearchError


def checkout_root(
    source: Path | str | None, env: str, *, command: str, repo: str, commit: str, doc: str
) -> Path:
    """The checkout's folder: ``source``, else ``$env``. Raises :class:`ObjsearchError` when
    neither names one (saying what ``command`` needs: ``repo`` at ``commit``, see ``doc``) or
    when it is no folder."""
    if source is None or str(source) == "":
        source = os.environ.get(env, "")
        if not source:
            raise ObjsearchError(
                f"{command} needs a checkout of {repo} at commit {commit}: pass --source DIR or "
                f"set ${env} ({doc})"
            )
    root = Path(source)
    if not root.is_dir():
        raise ObjsearchError(f"--source {root}: no such folder")
    return root
