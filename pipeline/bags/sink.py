"""The seam between a bag's two readers and what their messages feed: the
:class:`MessageSink` protocol, and :data:`Deserialize`, the reader's deserialiser a sink is handed."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable
from typing import Any, Protocol

from objsearch.pipeline.bags.salvage import RawConnection

Deserialize = Callable[[bytes, str], Any]


class MessageSink(Protocol):
    """What the two readers (``AnyReader``, the salvage scan) feed a bag's messages into: the
    event :class:`~objsearch.pipeline.bags.converter.Converter`, or ``rgbd.ViewCollector`` for map building."""

    def plan(
        self, conns: Iterable[RawConnection], known: Callable[[RawConnection], str | None]
    ) -> None:
        """Decide per connection whether it is read (``known`` says why a type cannot be)."""

    def wants(self, conn_id: int) -> bool: ...

    def count(self, conn_id: int, n: int = 1) -> None:
        """Count messages that are not read (from an index)."""

    def feed(self, conn_id: int, log_ns: int, raw: bytes, deserialize: Deserialize) -> None: ...

    def end_of_messages(self) -> None:
        """After the last message, while the reader is still open (its deserialiser works only
        then): a sink that collected messages converts them now."""

    def messages_per_topic(self) -> Counter[str]: ...
