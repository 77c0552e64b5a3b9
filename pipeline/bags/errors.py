"""Errors of the bag pipeline. All are :class:`ObjsearchError`, so the CLI reports them cleanly."""

from __future__ import annotations

from objsearch.agent.errors import ObjsearchError


class BagError(ObjsearchError):
    """A bag cannot be used at all (missing, not a bag, unknown format)."""


class BagConfigError(ObjsearchError):
    """A topic map or option is invalid."""


class BagCommitError(ObjsearchError):
    """The lake refused or failed a commit (nothing of the bag was committed)."""
