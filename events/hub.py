"""One fold per process: a hub restored from one snapshot that hands each event to every
projection registered with it, then to the observers that read them.

A process that keeps several projections of one log (the on-robot agent: its own state and its
``where`` memory; the live view reads the former) restores them together — one snapshot file,
one read of the log after it — and feeds them from one place, so none folds the log on its own.
The fold's checks (no event skipped, none applied twice, every projection advanced to the
event's seq) are made once here, for all of them.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Generic, TypeVar

from .envelope import Event
from .errors import ProjectionError
from .log_read import read_log
from .projection import EventObserver, EventView, end_sharing, fold, share_decodes
from .snapshot import Restored, Snapshottable, restore
from .store import Store

P = TypeVar("P", bound=Snapshottable)


@dataclass(frozen=True, slots=True)
class Member(Generic[P]):
    """A projection a hub restores: its name in the hub, a fresh one, and one from its snapshot
    state (the state its ``to_snapshot`` wrote, and the seq it was taken at)."""

    name: str
    fresh: Callable[[], P]
    from_snapshot: Callable[[dict[str, Any], int], P]


class ProjectionHub:
    """The projections of one log, folded together (a :class:`Snapshottable` itself).

    ``apply`` gives each event to every projection in the order they were registered, checks that
    each advanced to the event's seq, then tells the observers (:meth:`follow`: views that read
    the projections' state, never snapshotted). While it does, what a domain's decoder builds
    from the event is shared (:func:`~objsearch.events.projection.shared_decodes`): each record
    is decoded once, however many projections read it. ``applied`` counts the events given.
    """

    snapshot_name: ClassVar[str] = "projections"
    #: The hub's own layout; each member's name and version are checked inside it.
    snapshot_version: ClassVar[int] = 1

    def __init__(self, projections: Mapping[str, Snapshottable]) -> None:
        seqs = {p.last_seq for p in projections.values()}
        if len(seqs) > 1:
            raise ProjectionError(f"a hub's projections must be at one seq, not {sorted(seqs)}")
        self.projections = dict(projections)
        self._folds = tuple(self.projections.values())
        self.observers: list[EventObserver] = []
        self.last_seq = seqs.pop() if seqs else 0
        self.applied = 0

    @property
    def state(self) -> Mapping[str, Snapshottable]:
        return self.projections

    def __getitem__(self, name: str) -> Snapshottable:
        return self.projections[name]

    def follow(self, observer: EventObserver) -> None:
        """Tell ``observer`` of every event from now on, after every projection applied it."""
        self.observers.append(observer)

    def apply(self, event: EventView) -> None:
        assert isinstance(event, Event)  # the log's events (an EventObserver of the recorder)
        expected = self.last_seq + 1
        if event.seq != expected:
            raise ProjectionError(
                f"the hub is at seq {self.last_seq} and cannot apply seq {event.seq} "
                f"({event.type}): the next is {expected}"
            )
        seq = event.seq
        sharing = share_decodes(event)  # each record is built once, whoever asks for it first
        try:
            for projection in self._folds:
                projection.apply(event)
                if projection.last_seq != seq:
                    name = next(n for n, p in self.projections.items() if p is projection)
                    raise ProjectionError(
                        f"{name}: apply(seq {seq}) left last_seq at {projection.last_seq}"
                    )
            self.last_seq = seq
            self.applied += 1
            for observer in self.observers:
                observer.apply(event)
        finally:
            end_sharing(sharing)

    def to_snapshot(self) -> dict[str, Any]:
        return {
            name: {
                "projection": p.snapshot_name,
                "version": p.snapshot_version,
                "state": p.to_snapshot(),
            }
            for name, p in self.projections.items()
        }


def _fresh(members: Sequence[Member[Any]]) -> ProjectionHub:
    return ProjectionHub({m.name: m.fresh() for m in members})


def _from_snapshot(members: Sequence[Member[Any]], doc: dict[str, Any], seq: int) -> ProjectionHub:
    if sorted(doc) != sorted(m.name for m in members):
        raise ValueError(f"it holds {sorted(doc)}, not {sorted(m.name for m in members)}")
    projections: dict[str, Snapshottable] = {}
    for m in members:
        part = doc[m.name]
        fresh = m.fresh()
        if (part["projection"], part["version"]) != (fresh.snapshot_name, fresh.snapshot_version):
            raise ValueError(
                f"{m.name} is {part['projection']} v{part['version']}, the code's "
                f"{fresh.snapshot_name} v{fresh.snapshot_version}"
            )
        projections[m.name] = m.from_snapshot(part["state"], seq)
    return ProjectionHub(projections)


def restore_hub(
    log_dir: Path,
    members: Sequence[Member[Any]],
    *,
    snapshot_dir: Path | None,
    store: Store,
) -> tuple[ProjectionHub, Restored]:
    """The hub of ``members`` at the log's end: from its snapshot in ``snapshot_dir`` (one file,
    trusted as :func:`~objsearch.events.snapshot.restore` trusts one) and the events after it,
    else by one fold of the whole log. Saving is the caller's (:func:`save_snapshot` of the hub,
    attested by the log's writer)."""
    if snapshot_dir is None:
        hub = fold(read_log(log_dir, store=store), _fresh(members))
        return hub, Restored(0, hub.applied, None)
    return restore(
        log_dir,
        lambda: _fresh(members),
        lambda doc, seq: _from_snapshot(members, doc, seq),
        snapshot_dir=snapshot_dir,
        save=False,
        store=store,
    )
