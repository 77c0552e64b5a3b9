"""A bag's report: per topic what was read, converted, rejected and lost (:class:`TopicReport`,
:class:`Skipped`, :class:`TopicLoss`), the whole bag's (:class:`BagReport`, with its rendering),
and the rows built from a :class:`~objsearch.pipeline.bags.converter.Converter`."""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass

from objsearch.pipeline.bags.clock import ClockMap, iso
from objsearch.pipeline.bags.converter import Converter, TopicState
from objsearch.pipeline.bags.salvage import Loss
from objsearch.ros.topics import CONVERTED, Role

MAX_REASONS = 3


@dataclass(frozen=True, slots=True)
class TopicLoss:
    """Messages of one topic the bag says it holds that were not read, and where they went."""

    claimed: int
    lost: int
    reasons: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class TopicReport:
    topic: str
    msgtype: str
    role: str
    messages: int  # messages of the topic in the bag (read, or counted from its index)
    events: int  # events made from them
    rejected: int  # dropped as damaged or invalid
    reasons: tuple[str, ...] = ()
    #: Messages the bag's own index/metadata says the topic has (None: no claim survived).
    claimed: int | None = None
    #: Of those, not read at all (the bag is damaged there), and why where known. None: not
    #: known, because the bag's claims do not cover all of it (a cut bag); ``lost_reasons``
    #: then starts with the lower bound ("at least N") when there is one.
    lost: int | None = 0
    lost_reasons: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class Skipped:
    topic: str
    msgtype: str
    messages: int
    reason: str
    lost: int | None = 0  # claimed by the bag's index but not read (see TopicReport.lost)


@dataclass(frozen=True, slots=True)
class BagReport:
    path: str
    format: str
    bag_id: str
    size_bytes: int
    reader: str  # "AnyReader" or "salvage scan (...)"
    topics: tuple[TopicReport, ...]
    skipped: tuple[Skipped, ...]
    losses: tuple[Loss, ...]
    start_ns: int | None
    end_ns: int | None
    events: int
    event_types: Mapping[str, int]
    notes: tuple[str, ...] = ()
    #: Whether the bag's claims cover all of it; if not, the per-topic ``lost`` are lower bounds.
    claims_complete: bool = True
    #: Added to the agent events' ``time_ns`` to put them on their header stamps' clock (0:
    #: not moved).
    clock_offset_ns: int = 0
    #: How receive times were mapped onto the agent's clock (None: they agree, or no agent
    #: event has a header stamp): :mod:`~objsearch.pipeline.bags.clock`.
    clock: ClockMap | None = None
    #: The recorder's receive times of the first and last converted message, as stored in the
    #: bag (``start_ns``/``end_ns`` are on the run's clock).
    received_start_ns: int | None = None
    received_end_ns: int | None = None
    #: (receive time, header stamp) of up to :data:`~objsearch.pipeline.bags.clock.MAX_PAIRS`
    #: agent events: what the clock was fitted over (a session fits its pieces' together).
    clock_pairs: tuple[tuple[int, int], ...] = ()

    @property
    def damaged(self) -> bool:
        return (
            bool(self.losses)
            or any(t.rejected or t.lost or t.lost is None for t in self.topics)
            or any(s.lost or s.lost is None for s in self.skipped)
        )

    def render(self) -> str:
        lines = [
            f"{self.path} ({self.format}, {self.size_bytes:,} bytes, id {self.bag_id[:16]}, read by {self.reader})"
        ]
        if self.start_ns is not None and self.end_ns is not None:
            lines.append(
                f"  time range {iso(self.start_ns)} → {iso(self.end_ns)} "
                f"({(self.end_ns - self.start_ns) / 1e9:.1f} s)"
            )
        for t in self.topics:
            extra = f", {t.rejected} rejected ({'; '.join(t.reasons)})" if t.rejected else ""
            if t.lost or t.lost is None:
                extra += f", {_lost(t.lost)} lost"
                extra += f" ({'; '.join(t.lost_reasons)})" if t.lost_reasons else ""
            lines.append(
                f"  {t.topic:32} {t.msgtype:36} {t.role:12} {t.messages:8} msgs → {t.events} events{extra}"
            )
        for s in self.skipped:
            lost = f", {_lost(s.lost)} lost" if s.lost or s.lost is None else ""
            lines.append(f"  skipped {s.topic} ({s.msgtype}, {s.messages} msgs{lost}): {s.reason}")
        for loss in self.losses:
            lines.append(f"  LOST {loss}")
        for note in self.notes:
            lines.append(f"  note: {note}")
        types = ", ".join(f"{k} {v}" for k, v in sorted(self.event_types.items()))
        lines.append(f"  {self.events} events ({types or 'none'})")
        return "\n".join(lines)


def _lost(n: int | None) -> str:
    return "an unknown number" if n is None else str(n)


def _unknown(loss: TopicLoss | None) -> tuple[str, ...]:
    """The reasons of a loss the bag's claims cannot count: the lower bound first."""
    if loss is None or not loss.lost:
        return ("the bag's claims do not cover all of it (cut)",)
    return (f"at least {loss.lost}", *loss.reasons)


def topic_rows(
    conv: Converter,
    claimed: Mapping[str, int],
    losses: Mapping[str, TopicLoss],
    exact: bool = True,
) -> tuple[TopicReport, ...]:
    """One row per (topic, type): a topic recorded by several publishers has one connection each.

    A topic's losses go on its first row; a topic the bag claims messages of whose connection
    was never read (its declaration was lost with the damage) gets a row of its own. Unless the
    claims are ``exact`` (they cover the whole bag), no topic's loss is known: ``lost`` is None.
    """
    merged: dict[tuple[str, str], TopicState] = {}
    for s in conv.topics.values():
        key = (s.conn.topic, s.conn.msgtype)
        if key not in merged:
            merged[key] = TopicState(s.conn, s.role)
        m = merged[key]
        m.messages += s.messages
        m.events += s.events
        m.rejected.update(s.rejected)
    rows = []
    placed = {c.topic for c, _ in conv.skipped.values()}
    for (topic, msgtype), m in sorted(merged.items()):
        first = topic not in placed
        loss = losses.get(topic) if first else None
        placed.add(topic)
        role = m.role.value if m.role in CONVERTED else f"{m.role.value} (counted, not converted)"
        if m.role in (Role.TF, Role.TF_STATIC) and m.events == 0 and m.messages:
            f = conv.map.frames
            role += f" (no {f.map}→{f.odom} or {f.odom}/{f.map}→{f.base} transform, or odometry gives the poses)"
        rows.append(
            TopicReport(
                topic,
                msgtype,
                role,
                m.messages,
                m.events,
                sum(m.rejected.values()),
                tuple(r for r, _ in m.rejected.most_common(MAX_REASONS)),
                claimed.get(topic) if first else None,
                (0 if loss is None else loss.lost) if exact else None,
                (() if loss is None else loss.reasons) if exact else _unknown(loss),
            )
        )
    for topic, loss in sorted(losses.items()):
        if topic not in placed:
            rows.append(
                TopicReport(
                    topic,
                    "",
                    "unknown (no declaration of the topic could be read)",
                    0,
                    0,
                    0,
                    (),
                    loss.claimed,
                    loss.lost if exact else None,
                    loss.reasons if exact else _unknown(loss),
                )
            )
    return tuple(rows)


def skipped_rows(
    conv: Converter, losses: Mapping[str, TopicLoss], exact: bool = True
) -> tuple[Skipped, ...]:
    merged: Counter[tuple[str, str, str]] = Counter()
    for cid, (c, reason) in conv.skipped.items():
        merged[(c.topic, c.msgtype, reason)] += conv.skipped_messages[cid]
    rows = []
    placed: set[str] = set()
    for (t, m, r), n in sorted(merged.items()):
        loss = None if t in placed else losses.get(t)
        placed.add(t)
        lost = (0 if loss is None else loss.lost) if exact else None
        rows.append(Skipped(t, m, n, r, lost))
    return tuple(rows)
