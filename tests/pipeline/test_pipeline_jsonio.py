"""Canonical JSON and atomic writes."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from objsearch.pipeline import jsonio


def test_canonical_rounds_sorts_and_ends_with_newline() -> None:
    text = jsonio.dumps({"b": (1.23456789, -0.0), "a": {"z": True, "y": None}})
    assert text == (
        '{\n  "a": {\n    "y": null,\n    "z": true\n  },\n  "b": [\n    1.2346,\n    0.0\n  ]\n}\n'
    )


def test_non_finite_numbers_are_refused() -> None:
    with pytest.raises(ValueError, match="non-finite"):
        jsonio.dumps({"x": float("nan")})


def test_failed_write_keeps_the_old_file_and_leaves_no_temporary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    target = tmp_path / "sub" / "f.json"
    jsonio.write_atomic(target, b"old\n")

    def broken_replace(src: object, dst: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk full"):
        jsonio.write_atomic(target, b"new\n")
    assert target.read_bytes() == b"old\n"
    assert sorted(p.name for p in target.parent.iterdir()) == ["f.json"]
