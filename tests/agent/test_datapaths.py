"""Where the data is found, and where ``objsearch data build`` may write, from a checkout."""

from __future__ import annotations

import sysconfig
from pathlib import Path

import pytest

from objsearch.agent.datapaths import (
    DATA_ENV,
    DataLocationError,
    build_output_dir,
    checkout_data_dir,
    data_dir,
    packaged_data_dir,
)

REPO_DATA = Path(__file__).resolve().parents[2] / "data"


def test_the_packaged_data_is_the_checkouts_data_folder(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(DATA_ENV, raising=False)
    assert packaged_data_dir() == REPO_DATA
    assert data_dir() == REPO_DATA
    assert checkout_data_dir() == REPO_DATA
    assert (data_dir() / "homes" / "paper.json").is_file()


def test_objsearch_data_overrides(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    assert data_dir() == tmp_path
    assert build_output_dir(None) == tmp_path


def test_build_writes_to_the_checkout_by_default(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(DATA_ENV, raising=False)
    assert build_output_dir(None) == REPO_DATA
    assert build_output_dir("elsewhere") == Path("elsewhere")


def test_build_refuses_site_packages(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(DATA_ENV, raising=False)
    inside = Path(sysconfig.get_path("purelib")) / "objsearch" / "data"
    with pytest.raises(DataLocationError, match="refusing to write into the installed package"):
        build_output_dir(inside)
    monkeypatch.setenv(DATA_ENV, str(inside))  # a setting cannot smuggle it in either
    with pytest.raises(DataLocationError, match="refusing"):
        build_output_dir(None)
