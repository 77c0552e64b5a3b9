"""objsearch.events: the event envelope, versioned payload schemas, the append-only log and
projection plumbing. Knows nothing of robots.

See ``docs/events.md`` for the on-disk format and the guarantees.
"""

from .envelope import EVENT_ID_NAMESPACE, Event, deterministic_event_id
from .errors import (
    CorruptLogError,
    EventStoreError,
    InvalidEventError,
    LogClosedError,
    LogLockedError,
    LogNotFoundError,
    ProjectionError,
    StreamMismatchError,
    TornTailWarning,
)
from .log import EventLog, TornTail, read_log
from .projection import Projection, fold
from .schemas import SchemaRegistry, default_registry

__all__ = [
    "EVENT_ID_NAMESPACE",
    "CorruptLogError",
    "Event",
    "EventLog",
    "EventStoreError",
    "InvalidEventError",
    "LogClosedError",
    "LogLockedError",
    "LogNotFoundError",
    "Projection",
    "ProjectionError",
    "SchemaRegistry",
    "StreamMismatchError",
    "TornTail",
    "TornTailWarning",
    "default_registry",
    "deterministic_event_id",
    "fold",
    "read_log",
]
