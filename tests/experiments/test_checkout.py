"""Finding a pinned public checkout: --source, else the environment variable, else a clear error."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.agent.errors import ObjsearchError
from objsearch.experiments.checkout import checkout_root

ENV = "OBJSEARCH_TEST_CHECKOUT"
PIN = {"command": "bench x", "repo": "owner/name", "commit": "abc123", "doc": "docs/x.md"}


def test_neither_source_nor_variable_names_what_is_needed(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(ENV, raising=False)
    with pytest.raises(ObjsearchError) as caught:
        checkout_root(None, ENV, **PIN)
    assert str(caught.value) == (
        "bench x needs a checkout of owner/name at commit abc123: pass --source DIR or set "
        f"${ENV} (docs/x.md)"
    )


def test_the_source_wins_over_the_variable_and_must_be_a_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(ENV, str(tmp_path / "elsewhere"))
    assert checkout_root(tmp_path, ENV, **PIN) == tmp_path
    with pytest.raises(ObjsearchError, match="no such folder"):
        checkout_root("", ENV, **PIN)  # empty: the variable's, which does not exist
    monkeypatch.setenv(ENV, str(tmp_path))
    assert checkout_root("", ENV, **PIN) == tmp_path
