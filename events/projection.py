"""Projection plumbing: derived state is a fold of a stream's events in seq order.

The domain projections (scene graph, maps, experience) live with the domain; this module only
fixes the contract and the loop, including the checks that make a fold trustworthy: no event
is skipped, none is applied twice, and the projection really records how far it got.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from contextvars import ContextVar, Token
from typing import Any, Protocol, TypeVar

from .envelope import Event
from .errors import ProjectionError

S_co = TypeVar("S_co", covariant=True)


class EventView(Protocol):
    """What a fold reads of an event: its place in the stream, its type, its task and its
    payload (at the type's latest version, as ``read_log`` upcasts it). :class:`Event` is one;
    the domain's folds take this, so they never depend on how the log builds its events."""

    @property
    def seq(self) -> int: ...
    @property
    def type(self) -> str: ...
    @property
    def task_id(self) -> str | None: ...
    @property
    def payload(self) -> Mapping[str, Any]: ...


class Projection(Protocol[S_co]):
    """State built by applying one stream's events in seq order."""

    @property
    def last_seq(self) -> int:
        """Seq of the last event applied; 0 before any (or the seq a snapshot was taken at)."""
        ...

    @property
    def state(self) -> S_co:
        """The derived state (what the domain reads)."""
        ...

    def apply(self, event: Event) -> None:
        """Apply the next event (seq ``last_seq + 1``) and advance ``last_seq`` to its seq."""
        ...


class EventObserver(Protocol):
    """Told of each event of a log as it is appended or folded: a projection (which also
    satisfies :class:`Projection`), or a view or publisher that keeps no state of its own."""

    def apply(self, event: EventView) -> None: ...


#: While a hub hands out one event (:class:`~objsearch.events.hub.ProjectionHub`): that event and
#: what a domain's decoder has built from it so far, keyed as the decoder likes (a record type).
_SHARED: ContextVar[tuple[object, dict[Any, Any]] | None] = ContextVar(
    "objsearch_shared_decodes", default=None
)


def shared_decodes(event: object) -> dict[Any, Any] | None:
    """Where to keep what is decoded from ``event`` while a hub hands it to its projections, so
    they share one decode of each kind; None outside a hub (decode as usual). Scoped to the
    hub's ``apply`` on this thread: nothing outlives the event's hand-out."""
    shared = _SHARED.get()
    if shared is not None and shared[0] is event:
        return shared[1]
    return None


def share_decodes(event: object) -> Token[tuple[object, dict[Any, Any]] | None]:
    """Start sharing the decodes of ``event`` (the hub's; end with :func:`end_sharing`)."""
    return _SHARED.set((event, {}))


def end_sharing(token: Token[tuple[object, dict[Any, Any]] | None]) -> None:
    _SHARED.reset(token)


P = TypeVar("P", bound=Projection[Any])


def fold(events: Iterable[Event], projection: P, *, until_seq: int | None = None) -> P:
    """Apply ``events`` to ``projection`` in order and return it (the same object).

    Events the projection already has (``seq <= last_seq``) are skipped, so a projection restored
    from a snapshot can be folded over the whole log; a gap raises :class:`ProjectionError`.
    With ``until_seq`` the fold stops once that seq is applied, without consuming further events
    from an iterator, which gives the state "as of" any point in the stream.
    """
    if until_seq is not None and projection.last_seq > until_seq:
        raise ProjectionError(
            f"{type(projection).__name__} is already at seq {projection.last_seq}; "
            f"it cannot be folded back to seq {until_seq}"
        )
    if until_seq is not None and projection.last_seq == until_seq:
        return projection
    apply = projection.apply  # once, not per event: a fold of a log is millions of calls

    def checked(event: Event) -> None:
        seq = event.seq
        if seq != projection.last_seq + 1:
            raise ProjectionError(
                f"{type(projection).__name__} is at seq {projection.last_seq} and cannot apply "
                f"seq {seq} ({event.type}): events {projection.last_seq + 1}..{seq - 1} are "
                "missing"
            )
        apply(event)
        if projection.last_seq != seq:
            raise ProjectionError(
                f"{type(projection).__name__}.apply(seq {seq}) left last_seq at "
                f"{projection.last_seq}; apply must advance last_seq to the event's seq"
            )

    # A whole log from read_log, to a projection that folds records: no event per record.
    fold_into = getattr(events, "fold_into", None)
    if fold_into is not None and fold_into(projection, until_seq, checked):
        return projection
    for event in events:
        seq = event.seq
        if until_seq is not None and seq > until_seq:
            break
        expected = projection.last_seq + 1
        if seq < expected:
            continue
        if seq != expected:
            raise ProjectionError(
                f"{type(projection).__name__} is at seq {projection.last_seq} and cannot apply "
                f"seq {seq} ({event.type}): events {expected}..{seq - 1} are missing"
            )
        apply(event)
        if projection.last_seq != seq:
            raise ProjectionError(
                f"{type(projection).__name__}.apply(seq {seq}) left last_seq at "
                f"{projection.last_seq}; apply must advance last_seq to the event's seq"
            )
        if until_seq is not None and seq >= until_seq:
            break
    return projection
