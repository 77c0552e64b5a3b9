"""Canonical JSON."""

from __future__ import annotations

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
