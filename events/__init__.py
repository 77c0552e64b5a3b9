"""objsearch.events: the event envelope, versioned payload schemas, the append-only log and
projection plumbing. Knows nothing of robots.

See ``docs/events.md`` for the on-disk format and the guarantees.
"""

from .catalogue import Catalogue, install
from .envelope import EVENT_ID_NAMESPACE, Event, deterministic_event_id
from .errors import (
    CorruptLogError,
    DuplicateEventError,
    EventStoreError,
    InvalidEventError,
    LogClosedError,
    LogLockedError,
    LogNotFoundError,
    ObjsearchError,
    ProjectionError,
    StreamMismatchError,
    TornTailWarning,
    WrongExpectedSeqError,
)
from .log import EventLog, TornTail, follow_log, read_log
from .projection import Projection, fold
from .schemas import SchemaRegistry, default_registry
from .upcast import Upcaster, default_upcaster

__all__ = [
    "EVENT_ID_NAMESPACE",
    "Catalogue",
    "CorruptLogError",
    "DuplicateEventError",
    "Event",
    "EventLog",
    "EventStoreError",
    "InvalidEventError",
    "LogClosedError",
    "LogLockedError",
    "LogNotFoundError",
    "ObjsearchError",
    "Projection",
    "ProjectionError",
    "SchemaRegistry",
    "StreamMismatchError",
    "TornTail",
    "TornTailWarning",
    "Upcaster",
    "WrongExpectedSeqError",
    "default_registry",
    "default_upcaster",
    "deterministic_event_id",
    "fold",
    "follow_log",
    "install",
    "read_log",
]
