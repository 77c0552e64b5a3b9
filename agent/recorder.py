"""Where the agent's events go: a :class:`Recorder` appends each one to the log and hands it to
the projections, so the scene graph the next plan uses is always the fold of what was written."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

from objsearch.agent.catalogue import LATEST, STORE, Record
from objsearch.events import Event
from objsearch.events.projection import EventObserver, EventView

_log = logging.getLogger(__name__)


class EventSink(Protocol):
    """Where the agent's events go: the log (``EventLog``)."""

    def append_record(
        self, record: Record, *, time_ns: int, task_id: str | None = None
    ) -> EventView: ...


@dataclass
class Recorder:
    """Appends events and hands each one to its observers (the live projections among them).

    A stream's time never runs backwards (the log refuses it), but a robot's clock can step back
    (a restarted simulator, an NTP step): such an event is stamped with the last event's time
    instead, with one warning per step, so a clock never stops the agent.
    """

    sink: EventSink
    observers: Sequence[EventObserver]
    time_floor_ns: int = 0
    _behind: bool = field(default=False, init=False)

    def emit(self, record: Record, *, time_ns: int, task_id: str | None = None) -> EventView:
        """Append ``record`` stamped ``time_ns`` (or the last event's time, see above) and tell
        every observer of the event."""
        if time_ns < self.time_floor_ns:
            if not self._behind:
                _log.warning(
                    "the robot's clock stepped back %.3f s; events are stamped with the last "
                    "event's time until it catches up",
                    (self.time_floor_ns - time_ns) / 1e9,
                )
            self._behind = True
            time_ns = self.time_floor_ns
        else:
            self._behind = False
            self.time_floor_ns = time_ns
        event = self.sink.append_record(record, time_ns=time_ns, task_id=task_id)
        if type(record).VERSION < LATEST[record.TYPE].VERSION and isinstance(event, Event):
            # An older version kept for byte-identical logs (a perfect detector's v2
            # detection): observers read latest versions, as read_log hands them out.
            event = STORE.upcaster.upcast(event)
        for observer in self.observers:
            observer.apply(event)
        return event
