"""Errors the agent raises for bad input; each message says what was wrong and what would be right."""

from __future__ import annotations

# The project's one error root; defined in events, which imports nothing of objsearch.
from objsearch.events.errors import ObjsearchError as ObjsearchError


class UnknownObjectClassError(ObjsearchError, KeyError):
    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class NotATargetError(ObjsearchError, ValueError):
    """The class exists but cannot be searched for (static or dynamic objects)."""


class DataFileError(ObjsearchError, FileNotFoundError):
    """A derived data file is missing or unreadable."""


class UnknownStartError(ObjsearchError, KeyError):
    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""
