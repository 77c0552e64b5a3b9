"""objsearch.events: the event envelope, versioned payload schemas, the append-only log and
projection plumbing. Knows nothing of robots: a domain builds a :class:`Store` from its
:class:`Catalogue` and hands it to what reads and writes its events.

See ``docs/events.md`` for the on-disk format and the guarantees.
"""

from .catalogue import Catalogue
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
from .log import EventLog
from .log_files import TornTail
from .log_read import follow_log, read_log
from .projection import EventView, Projection, fold
from .schemas import SchemaRegistry
from .store import Store, shipped
from .upcast import Upcaster

__all__ = [
    "EVENT_ID_NAMESPACE",
    "Catalogue",
    "CorruptLogError",
    "DuplicateEventError",
    "Event",
    "EventLog",
    "EventStoreError",
    "EventView",
    "InvalidEventError",
    "LogClosedError",
    "LogLockedError",
    "LogNotFoundError",
    "ObjsearchError",
    "Projection",
    "ProjectionError",
    "SchemaRegistry",
    "Store",
    "StreamMismatchError",
    "TornTail",
    "TornTailWarning",
    "Upcaster",
    "WrongExpectedSeqError",
    "deterministic_event_id",
    "fold",
    "follow_log",
    "read_log",
    "shipped",
]
