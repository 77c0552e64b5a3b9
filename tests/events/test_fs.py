"""The one atomic write: old or new file, never a torn one, and no temporary left behind."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from objsearch.events import _fs


def test_write_atomic_replaces_the_file(tmp_path: Path) -> None:
    target = tmp_path / "f.json"
    _fs.write_atomic(target, b"old\n")
    _fs.write_atomic(target, b"new\n")
    assert target.read_bytes() == b"new\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.json"]


def test_failed_write_keeps_the_old_file_and_leaves_no_temporary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    target = tmp_path / "f.json"
    _fs.write_atomic(target, b"old\n")

    def broken_replace(src: object, dst: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk full"):
        _fs.write_atomic(target, b"new\n")
    assert target.read_bytes() == b"old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.json"]


def test_make_dirs_then_write_creates_missing_folders(tmp_path: Path) -> None:
    target = tmp_path / "a" / "b" / "f.json"
    _fs.make_dirs(target.parent)
    _fs.write_atomic(target, b"x")
    assert target.read_bytes() == b"x"
