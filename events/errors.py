"""Errors and warnings of the event store.

Every error derives from :class:`EventStoreError`, so a caller can catch the store's failures in
one place; several also derive from the built-in they refine (``ValueError``,
``FileNotFoundError``) so generic handlers keep working.

:class:`ObjsearchError`, the root of every error the project raises on purpose, lives here because
``events`` is the package every other one may import and it imports none of them: the agent, the
pipeline, the runtime and the CLI derive their errors from it (``objsearch.agent.errors``
re-exports it), and the CLI catches that one class.
"""

from __future__ import annotations


class ObjsearchError(Exception):
    """Base of every error objsearch reports to a user (the CLI turns them into exit code 2)."""


class EventStoreError(ObjsearchError):
    """Base class of every error raised by ``objsearch.events``."""


class InvalidEventError(EventStoreError, ValueError):
    """An event (envelope or payload) does not match its schema; nothing was written.

    ``event_type``, ``version``, ``path`` (e.g. ``"payload.values[2].rel"``) and ``reason`` are
    kept apart from the message so callers and tests need not parse it.
    """

    def __init__(
        self,
        message: str,
        *,
        event_type: str | None = None,
        version: int | None = None,
        path: str | None = None,
        reason: str | None = None,
    ) -> None:
        super().__init__(message)
        self.event_type = event_type
        self.version = version
        self.path = path
        self.reason = reason


class CorruptLogError(EventStoreError):
    """A record that is not a torn tail is damaged; the log needs a human, not a heuristic."""

    def __init__(self, message: str, *, path: str, line: int, offset: int) -> None:
        super().__init__(message)
        self.path = path
        self.line = line
        self.offset = offset


class LogNotFoundError(EventStoreError, FileNotFoundError):
    """There is no event log where one was expected."""


class LogLockedError(EventStoreError):
    """Another writer holds the log's lock; a stream has exactly one writer."""


class LogClosedError(EventStoreError, ValueError):
    """The writer was closed, or disabled after a failed write or fsync."""


class StreamMismatchError(EventStoreError, ValueError):
    """The log belongs to another stream than the one asked for."""


class DuplicateEventError(EventStoreError, ValueError):
    """An append reuses an event id already in the stream for a different fact."""


class WrongExpectedSeqError(EventStoreError):
    """An append's ``expected_last_seq`` is not where the log ends (someone else appended)."""


class ProjectionError(EventStoreError):
    """Events reached a projection out of order, or the projection did not advance."""


class TornTailWarning(UserWarning):
    """An interrupted, never-acknowledged append at the end of a log was cut (or skipped)."""
