"""Errors the data converter raises; each names what is wrong and what it was needed for."""

from __future__ import annotations

from pathlib import Path

from objsearch.events.errors import ObjsearchError


class BuildError(ObjsearchError):
    """Base of every error the converter raises on purpose."""


class SourceDataError(BuildError):
    """A raw source file is missing or does not look the way the converter needs it."""

    def __init__(self, path: Path, needed_for: str, problem: str = "missing source file") -> None:
        self.path = path
        self.needed_for = needed_for
        self.problem = problem
        super().__init__(f"{problem}: {path} (needed for {needed_for})")


class HomeSpecError(BuildError, ValueError):
    """A requested home is malformed (wrong room count, wrong room type, bad name)."""
