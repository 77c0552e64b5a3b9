"""A bag of any format → events and a report. Pure: reads the bag, writes nothing.

``read_bag`` first reads with rosbags' ``AnyReader`` (index-driven, fast). If that fails
anywhere — a bag cut short, a damaged index or chunk — it starts again with the salvage scanners
of :mod:`objsearch.pipeline.bags.salvage` and reports what could not be read. Either way each
message goes through the same conversion:

* ``objsearch_msgs/Event`` → the agent's own event, envelope and payload exactly as logged,
  checked against the envelope rules and the payload's JSON Schema (else rejected);
* ``nav_msgs/Odometry`` → ``pose_observed`` (composed with map → odom from TF when known);
  TF to the base frame does the same when a bag has no odometry topic;
* ``vision_msgs/Detection2DArray`` → ``objects_detected``.

Messages that do not deserialise, or carry non-finite numbers, a non-unit quaternion or
implausible coordinates, are rejected and counted, never converted. Derived events get the
stream ``bag:<first 16 hex of the bag id>`` and ids from (stream, seq), so the same bag always
yields the same events.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import sys
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final, Protocol, TypeVar

import numpy as np
import pyarrow as pa

from objsearch.agent.catalogue import STORE
from objsearch.events import Event, InvalidEventError, deterministic_event_id
from objsearch.events.arrow import events_to_tables
from objsearch.events.record import encode_record
from objsearch.pipeline.bags import fastdecode
from objsearch.pipeline.bags.census import Census, take_census
from objsearch.pipeline.bags.clock import ClockMap, fit_clock, kept_pairs
from objsearch.pipeline.bags.errors import BagError
from objsearch.pipeline.bags.formats import BagFormat, detect, storage_files
from objsearch.pipeline.bags.posetrack import (
    POSE_TYPE,
    PoseSource,
    PoseTrack,
    convert_sources,
    coord,
)
from objsearch.pipeline.bags.salvage import Loss, RawConnection, Scan, scan_bag
from objsearch.ros.topics import ACCEPTED_TYPES, CONVERTED, Role, TopicMap
from objsearch.ros.types import Distro, typestore

PROGRESS_MIN_MESSAGES = 20_000
MAX_REASONS = 3

Deserialize = Callable[[bytes, str], Any]


class MessageSink(Protocol):
    """What the two readers (``AnyReader``, the salvage scan) feed a bag's messages into: the
    event :class:`Converter`, or ``rgbd.ViewCollector`` for map building."""

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


Sink = TypeVar("Sink", bound=MessageSink)


@dataclass(frozen=True, slots=True)
class ReadOutcome:
    reader: str  # "AnyReader" or "salvage scan"
    losses: tuple[Loss, ...]
    notes: tuple[str, ...]
    #: Messages per topic the bag says it holds (the largest of its own claims:
    #: :mod:`~objsearch.pipeline.bags.census`).
    claimed: Mapping[str, int]
    #: False when no claim covers the whole bag (its index is gone): the losses are lower bounds.
    claims_complete: bool
    census: Census
    scans: tuple[Scan, ...] = ()  # the salvage scans, when the scanner read the bag


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
    #: Of those, not read at all (the bag is damaged there), and why where known.
    lost: int = 0
    lost_reasons: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class Skipped:
    topic: str
    msgtype: str
    messages: int
    reason: str
    lost: int = 0  # claimed by the bag's index but not read (see TopicReport.lost)


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
            or any(t.rejected or t.lost for t in self.topics)
            or any(s.lost for s in self.skipped)
        )

    def render(self) -> str:
        lines = [
            f"{self.path} ({self.format}, {self.size_bytes:,} bytes, id {self.bag_id[:16]}, read by {self.reader})"
        ]
        if self.start_ns is not None and self.end_ns is not None:
            lines.append(
                f"  time range {_iso(self.start_ns)} → {_iso(self.end_ns)} "
                f"({(self.end_ns - self.start_ns) / 1e9:.1f} s)"
            )
        for t in self.topics:
            extra = f", {t.rejected} rejected ({'; '.join(t.reasons)})" if t.rejected else ""
            if t.lost or not self.claims_complete:
                extra += f", {_lost(t.lost, self.claims_complete)} lost"
                extra += f" ({'; '.join(t.lost_reasons)})" if t.lost_reasons else ""
            lines.append(
                f"  {t.topic:32} {t.msgtype:36} {t.role:12} {t.messages:8} msgs → {t.events} events{extra}"
            )
        for s in self.skipped:
            lost = f", {_lost(s.lost, self.claims_complete)} lost" if s.lost else ""
            lines.append(f"  skipped {s.topic} ({s.msgtype}, {s.messages} msgs{lost}): {s.reason}")
        for loss in self.losses:
            lines.append(f"  LOST {loss}")
        for note in self.notes:
            lines.append(f"  note: {note}")
        types = ", ".join(f"{k} {v}" for k, v in sorted(self.event_types.items()))
        lines.append(f"  {self.events} events ({types or 'none'})")
        return "\n".join(lines)


@dataclass(frozen=True, slots=True)
class BagContents:
    """A bag's events: the agent's, the derived ones made one by one, and the pose track
    (columns; by far the most rows)."""

    report: BagReport
    agent: tuple[Event, ...]  # in (stream, seq) order
    derived: tuple[Event, ...]  # objects_detected, numbered among the poses
    poses: PoseTrack
    stream: str  # the derived events' stream

    @property
    def events(self) -> tuple[Event, ...]:
        """Every event: the agent's, then the derived ones in seq order."""
        poses = self.poses.events(self.stream)
        derived = sorted([*self.derived, *poses], key=lambda e: e.seq)
        return (*self.agent, *derived)

    def tables(self) -> dict[str, pa.Table]:
        """The lake's typed tables: ``events_to_tables(self.events)``, with the pose track's
        table built from its columns instead of an event per pose."""
        tables = events_to_tables([*self.agent, *self.derived], STORE)
        if len(self.poses):
            track = self.poses.table(self.stream)
            if POSE_TYPE in tables:  # the agent's own poses come first, as in self.events
                track = pa.concat_tables([tables[POSE_TYPE], track]).combine_chunks()
            tables[POSE_TYPE] = track
        return dict(sorted(tables.items()))


def _lost(n: int, exact: bool) -> str:
    return str(n) if exact else f"at least {n}"


def _iso(ns: int) -> str:
    import datetime as dt

    return dt.datetime.fromtimestamp(ns / 1e9, dt.UTC).isoformat(timespec="milliseconds")


def bag_identity(path: Path) -> tuple[str, int]:
    """sha256 over the bag's storage files (names and bytes) and their total size."""
    h = hashlib.sha256()
    size = 0
    for f in storage_files(path):
        h.update(f.name.encode() + b"\0")
        with f.open("rb") as fh:
            while block := fh.read(1 << 20):
                h.update(block)
                size += len(block)
    return h.hexdigest(), size


# -- conversion -------------------------------------------------------------------------------


_POSE_ROLES: Final = frozenset({Role.ODOMETRY, Role.TF, Role.TF_STATIC})


@dataclass
class _TopicState:
    conn: RawConnection
    role: Role
    messages: int = 0
    events: int = 0
    rejected: Counter[str] = field(default_factory=Counter)


class Converter:
    """Turns a bag's messages into events; one per bag.

    Odometry and TF messages are only collected while the bag is read (:class:`PoseSource`, one
    per connection) and converted together by :meth:`finish`
    (:mod:`~objsearch.pipeline.bags.posetrack`); the others are converted as they come.
    """

    def __init__(self, topic_map: TopicMap, bag_id: str, distro: Distro) -> None:
        self.map = topic_map
        self.distro = distro
        self.stream = f"bag:{bag_id[:16]}"
        self.registry = STORE.registry
        self.topics: dict[int, _TopicState] = {}
        self.skipped: dict[int, tuple[RawConnection, str]] = {}
        self.skipped_messages: Counter[int] = Counter()
        self.pose_sources: dict[int, PoseSource] = {}
        #: Other derived events, (bag time, topic, arrival, type, payload): numbered by finish()
        #: among the poses in (time, topic, arrival) order.
        self.derived: list[tuple[int, str, int, str, dict[str, Any]]] = []
        self.arrivals = 0  # converted messages fed so far: the order they came in
        #: The pose track and the other derived events, numbered: made by end_of_messages().
        self.numbered: tuple[PoseTrack, list[Event]] | None = None
        self.agent: dict[str, Event] = {}
        #: event id → the events topic's header stamp (ns), where the message had one
        self.stamps: dict[str, int] = {}
        #: event id → when the recorder received it (the bag's time of its message)
        self.received: dict[str, int] = {}
        self.duplicates = 0
        self.start_ns: int | None = None
        self.end_ns: int | None = None

    def plan(
        self, conns: Iterable[RawConnection], known: Callable[[RawConnection], str | None]
    ) -> None:
        """Decide per connection: convert, count only, or skip (with the reason)."""
        standard = typestore(self.distro).fielddefs
        for c in conns:
            if c.id in self.topics or c.id in self.skipped:
                continue
            role = self.map.role(c.topic)
            if role is None:
                hint = sorted(r.value for r, ts in ACCEPTED_TYPES.items() if c.msgtype in ts)
                reason = "not in the topic map"
                if hint:
                    reason += f" (its type would be read as {' or '.join(hint)}; map it in a --topics file)"
                elif c.msgtype not in standard:
                    reason += f" (custom type {c.msgtype}, defined only in the bag)"
                self.skipped[c.id] = (c, reason)
            elif c.msgtype not in ACCEPTED_TYPES[role]:
                self.skipped[c.id] = (
                    c,
                    f"mapped as {role.value}, which takes {', '.join(sorted(ACCEPTED_TYPES[role]))}, "
                    f"not {c.msgtype}",
                )
            elif role in CONVERTED and (why := known(c)) is not None:
                self.skipped[c.id] = (c, why)
            else:
                self.topics[c.id] = _TopicState(c, role)
                if role in _POSE_ROLES:
                    tf = role is not Role.ODOMETRY
                    layouts = fastdecode.TF_LAYOUT if tf else fastdecode.ODOMETRY_LAYOUT
                    self.pose_sources[c.id] = PoseSource(
                        c.topic, c.msgtype, tf, layouts[self.distro]
                    )

    def wants(self, conn_id: int) -> bool:
        state = self.topics.get(conn_id)
        return state is not None and state.role in CONVERTED

    def count(self, conn_id: int, n: int = 1) -> None:
        """Count messages without reading them (from an index)."""
        if conn_id in self.topics:
            self.topics[conn_id].messages += n
        elif conn_id in self.skipped:
            self.skipped_messages[conn_id] += n

    def messages_per_topic(self) -> Counter[str]:
        counts: Counter[str] = Counter()
        for state in self.topics.values():
            counts[state.conn.topic] += state.messages
        for cid, (c, _) in self.skipped.items():
            counts[c.topic] += self.skipped_messages[cid]
        return counts

    def feed(self, conn_id: int, log_ns: int, raw: bytes, deserialize: Deserialize) -> None:
        state = self.topics.get(conn_id)
        if state is None:
            self.skipped_messages[conn_id] += 1
            return
        state.messages += 1
        if state.role not in CONVERTED:
            return
        self.arrivals += 1
        source = self.pose_sources.get(conn_id)
        if source is not None:
            source.add(log_ns, self.arrivals, raw, deserialize)
            return
        try:
            made = self._convert(state, log_ns, raw, deserialize)
        except InvalidEventError as exc:
            state.rejected[f"invalid event: {exc}"] += 1
            return
        except Exception as exc:
            state.rejected[f"{type(exc).__name__}: {exc}"[:200]] += 1
            return
        state.events += made
        self._accepted(log_ns, log_ns)

    def _accepted(self, first_ns: int, last_ns: int) -> None:
        self.start_ns = first_ns if self.start_ns is None else min(self.start_ns, first_ns)
        self.end_ns = last_ns if self.end_ns is None else max(self.end_ns, last_ns)

    def _convert(
        self, state: _TopicState, log_ns: int, raw: bytes, deserialize: Deserialize
    ) -> int:
        topic = state.conn.topic
        msg = deserialize(raw, state.conn.msgtype)
        if state.role is Role.DETECTIONS:
            payload = {
                "frame_id": msg.header.frame_id,
                "topic": topic,
                "detections": [_detection(d) for d in msg.detections],
            }
            self.derived.append((log_ns, topic, self.arrivals, "objects_detected", payload))
            return 1
        if state.role is Role.EVENTS:
            return self._agent_event(msg, log_ns)
        return 0

    def end_of_messages(self) -> None:
        if self.numbered is None:
            self.numbered = self._pose_track()

    def _pose_track(self) -> tuple[PoseTrack, list[Event]]:
        """Convert the collected odometry and TF, then number every derived event.

        Poses from TF only where the bag has no odometry; numbered in (time, topic, arrival)
        order, which is the same whichever reader (index or scan) delivered the messages.
        """
        sources = list(self.pose_sources.items())
        poses, outcomes = convert_sources([s for _, s in sources], self.map.frames)
        odometry = any(s.role is Role.ODOMETRY for s in self.topics.values())
        for (conn_id, source), outcome in zip(sources, outcomes, strict=True):
            state = self.topics[conn_id]
            # TF's poses are dropped below when odometry gives them: credit none to TF then.
            state.events += 0 if odometry and source.tf else outcome.events
            state.rejected.update(outcome.rejected)
            if outcome.first_ns is not None and outcome.last_ns is not None:
                self._accepted(outcome.first_ns, outcome.last_ns)
        if odometry:
            poses = poses.take(~poses.from_tf)
        topics = sorted({*poses.topics, *(d[1] for d in self.derived)})
        rank = np.array([topics.index(t) for t in poses.topics] + [0], dtype=np.int64)
        n_derived = len(self.derived)
        time = np.concatenate([poses.time, np.array([d[0] for d in self.derived], np.int64)])
        topic = np.concatenate(
            [rank[poses.topic], np.array([topics.index(d[1]) for d in self.derived], np.int64)]
        )
        arrival = np.concatenate([poses.arrival, np.array([d[2] for d in self.derived], np.int64)])
        index = np.concatenate([poses.index, np.zeros(n_derived, np.int64)])
        seq = np.empty(len(time), dtype=np.int64)
        seq[np.lexsort((index, arrival, topic, time))] = np.arange(1, len(time) + 1)
        pose_seq = seq[: len(poses.time)]
        order = np.argsort(pose_seq)
        track = PoseTrack(
            pose_seq[order],
            poses.time[order],
            poses.x[order],
            poses.y[order],
            poses.yaw[order],
            poses.frame[order],
            poses.topic[order],
            poses.frames,
            poses.topics,
        )
        # Event._adopt: the envelope's types are still checked, but no deep copy of a payload
        # this converter built from checked floats and strings (and owns), nor a parse of an id
        # deterministic_event_id just formatted. The payload's JSON Schema is enforced by the
        # lake's typed columns when the tables are built.
        derived = sorted(
            (
                Event._adopt(
                    {
                        "event_id": deterministic_event_id(self.stream, s),
                        "stream": self.stream,
                        "seq": s,
                        "time_ns": log_ns,
                        "recorded_at_ns": log_ns,
                        "type": type,
                        "version": 1,
                        "task_id": None,
                        "payload": payload,
                    }
                )
                for s, (log_ns, _, _, type, payload) in zip(
                    seq[len(poses.time) :].tolist(), self.derived, strict=True
                )
            ),
            key=lambda e: e.seq,
        )
        return track, derived

    def _agent_event(self, msg: Any, log_ns: int) -> int:
        try:
            payload = json.loads(msg.payload_json)
        except ValueError as exc:
            raise InvalidEventError(f"payload_json is not JSON: {exc}") from None
        event = Event(
            event_id=msg.event_id,
            stream=msg.stream,
            seq=int(msg.seq),
            time_ns=int(msg.time_ns),
            recorded_at_ns=int(msg.recorded_at_ns),
            type=msg.type,
            version=int(msg.version),
            task_id=msg.task_id or None,
            payload=payload,
        )
        crc = getattr(msg, "crc32", None)
        if crc is not None and int(encode_record(event)[-9:-1], 16) != int(crc):
            raise InvalidEventError("checksum mismatch: the message was damaged")
        self.registry.validate_event(event)
        if event.event_id in self.agent:
            if self.agent[event.event_id] != event:
                raise InvalidEventError(
                    f"event id {event.event_id} appears twice with different contents"
                )
            self.duplicates += 1
            return 0
        self.agent[event.event_id] = event
        self.received[event.event_id] = log_ns
        stamp = getattr(getattr(msg, "header", None), "stamp", None)
        if stamp is not None:
            stamp_ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
            if stamp_ns > 0:
                self.stamps[event.event_id] = stamp_ns
        return 1

    def finish(self) -> Finished:
        """All events (the agent's in (stream, seq) order, then derived), gaps as losses.

        One clock for all of them, the agent's: its events are moved onto their header stamps
        (:func:`clock_offset`), and derived events from receive times onto the same clock where
        the bag's receive times differ from those stamps (:mod:`..clock`)."""
        agent = sorted(self.agent.values(), key=lambda e: (e.stream, e.seq))
        losses: list[Loss] = []
        notes: list[str] = []
        offset = clock_offset(agent, self.stamps)
        if offset:
            agent = [_shifted(e, offset) for e in agent]
            notes.append(
                f"agent events moved onto their header stamps' clock: time_ns + {offset} ns "
                f"(the simulator's 0 is {_iso(offset)})"
            )
        pairs = kept_pairs(
            (self.received[e.event_id], self.stamps[e.event_id])
            for e in agent
            if e.event_id in self.stamps
        )
        clock = fit_clock(pairs)
        if clock is not None:
            notes.append(clock.describe())
        by_stream: dict[str, list[int]] = {}
        for e in agent:
            by_stream.setdefault(e.stream, []).append(e.seq)
        for stream, seqs in by_stream.items():
            missing = _gaps(seqs)
            if missing:
                n = sum(b - a + 1 for a, b in missing)
                spans = ", ".join(f"{a}" if a == b else f"{a}–{b}" for a, b in missing[:10])
                losses.append(Loss(f"agent stream {stream!r}", f"seq(s) {spans} missing", n))
            if seqs[0] != 1:
                notes.append(
                    f"agent stream {stream!r} starts at seq {seqs[0]} (recording began mid-run)"
                )
        if self.duplicates:
            notes.append(f"{self.duplicates} agent event(s) appeared more than once; kept once")
        self.end_of_messages()
        assert self.numbered is not None
        poses, derived = self.numbered
        if clock is not None:
            poses = poses.on_clock(clock.apply(poses.time))
            # recorded_at_ns keeps each derived event's receive time
            derived = [_shifted(e, clock.at(e.time_ns) - e.time_ns) for e in derived]
        return Finished(tuple(agent), tuple(derived), poses, losses, notes, offset, clock, pairs)

    def time_range(self, done: Finished) -> tuple[int | None, int | None]:
        """The first and last time of the bag's converted messages on the run's clock."""
        if self.start_ns is None or self.end_ns is None or done.clock is None:
            return self.start_ns, self.end_ns
        times = [e.time_ns for e in done.agent]
        start = min([done.clock.at(self.start_ns), *times])
        end = max([done.clock.at(self.end_ns), *times])
        return start, end


def clock_offset(agent: Sequence[Event], stamps: Mapping[str, int]) -> int:
    """What to add to the agent's ``time_ns`` to put it on its header stamps' clock: the header
    stamp of the events topic less the event's own ``time_ns``, from the lowest-seq event with a
    stamp (``record`` stamps each event at 2026-01-01 + its simulated time; ``rosbag record`` of
    a playback keeps the stamps). 0 if no event has a stamp."""
    for e in agent:
        if e.event_id in stamps:
            return stamps[e.event_id] - e.time_ns
    return 0


def _shifted(event: Event, offset: int) -> Event:
    doc = event.to_json_dict()
    doc["time_ns"] += offset
    return Event._adopt(doc)


@dataclass(frozen=True, slots=True)
class Finished:
    agent: tuple[Event, ...]
    derived: tuple[Event, ...]
    poses: PoseTrack
    losses: list[Loss]
    notes: list[str]
    clock_offset_ns: int = 0
    clock: ClockMap | None = None
    clock_pairs: tuple[tuple[int, int], ...] = ()

    def event_types(self) -> Counter[str]:
        types = Counter(e.type for e in self.agent)
        types.update(e.type for e in self.derived)
        if len(self.poses):
            types[POSE_TYPE] += len(self.poses)
        return types


def _topic_rows(
    conv: Converter, claimed: Mapping[str, int], losses: Mapping[str, TopicLoss]
) -> tuple[TopicReport, ...]:
    """One row per (topic, type): a topic recorded by several publishers has one connection each.

    A topic's losses go on its first row; a topic the bag claims messages of whose connection
    was never read (its declaration was lost with the damage) gets a row of its own.
    """
    merged: dict[tuple[str, str], _TopicState] = {}
    for s in conv.topics.values():
        key = (s.conn.topic, s.conn.msgtype)
        if key not in merged:
            merged[key] = _TopicState(s.conn, s.role)
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
                0 if loss is None else loss.lost,
                () if loss is None else loss.reasons,
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
                    loss.lost,
                    loss.reasons,
                )
            )
    return tuple(rows)


def _skipped_rows(conv: Converter, losses: Mapping[str, TopicLoss]) -> tuple[Skipped, ...]:
    merged: Counter[tuple[str, str, str]] = Counter()
    for cid, (c, reason) in conv.skipped.items():
        merged[(c.topic, c.msgtype, reason)] += conv.skipped_messages[cid]
    rows = []
    placed: set[str] = set()
    for (t, m, r), n in sorted(merged.items()):
        loss = None if t in placed else losses.get(t)
        placed.add(t)
        rows.append(Skipped(t, m, n, r, 0 if loss is None else loss.lost))
    return tuple(rows)


def _gaps(seqs: list[int]) -> list[tuple[int, int]]:
    gaps = []
    for a, b in itertools.pairwise(seqs):
        if b > a + 1:
            gaps.append((a + 1, b - 1))
    return gaps


def _detection(d: Any) -> dict[str, Any]:
    best = max(d.results, key=lambda r: hypothesis_score(r), default=None)
    center = d.bbox.center
    cx, cy = (
        (center.position.x, center.position.y)
        if hasattr(center, "position")
        else (center.x, center.y)
    )
    bbox = [float(cx), float(cy), float(d.bbox.size_x), float(d.bbox.size_y)]
    if not all(math.isfinite(v) for v in bbox):
        raise ValueError("bounding box has a non-finite value")
    position = None
    class_id, score = "", 0.0
    if best is not None:
        hyp = getattr(best, "hypothesis", best)
        class_id = str(getattr(hyp, "class_id", getattr(hyp, "id", "")))
        score = float(hyp.score)
        if not math.isfinite(score):
            raise ValueError("hypothesis score is not finite")
        pt = best.pose.pose.position
        position = [coord(pt.x), coord(pt.y), coord(pt.z)]
    return {
        "instance_id": str(getattr(d, "id", "")),
        "class_id": class_id,
        "score": score,
        "bbox": bbox,
        "position": position,
    }


def hypothesis_score(r: Any) -> float:
    return float(getattr(getattr(r, "hypothesis", r), "score", 0.0))


# -- reading ----------------------------------------------------------------------------------


def _type_checker(
    store_types: Mapping[str, Any], bag_defs: bool
) -> Callable[[RawConnection], str | None]:
    def known(c: RawConnection) -> str | None:
        if c.msgtype in store_types:
            return None
        return (
            f"custom type {c.msgtype}: the bag carries no definition for it"
            + (" that parses" if bag_defs else "")
            + " and neither the ROS typestore nor objsearch's .msg files define it"
        )

    return known


def _progress(total: int | None, enabled: bool, label: str) -> Any:
    from tqdm import tqdm

    show = enabled and (total is None or total >= PROGRESS_MIN_MESSAGES)
    # disable=None: drawn on a terminal only, never into a pipe or log (DEVELOPERS.md).
    off = None if show else True
    return tqdm(total=total, disable=off, file=sys.stderr, unit="msg", desc=label, leave=False)


_DEF_FORMATS = {"MSG": "msg", "IDL": "idl"}


def _read_anyreader(path: Path, fmt: BagFormat, conv: MessageSink, progress: bool) -> None:
    from rosbags.highlevel import AnyReader

    # A ROS 2 directory is recognised by AnyReader from a non-".bag" name; a ROS 1 file must end
    # in .bag for it, so a renamed ROS 1 bag is read by the scanner instead.
    if fmt is BagFormat.ROS1 and path.suffix != ".bag":
        raise BagError("ROS 1 bag without a .bag suffix")
    with AnyReader([path], default_typestore=typestore(fmt.distro)) as reader:
        conns = {
            c.id: RawConnection(
                c.id, c.topic, c.msgtype, c.msgdef.data, _DEF_FORMATS.get(c.msgdef.format.name, "")
            )
            for c in reader.connections
        }
        conv.plan(conns.values(), _type_checker(reader.typestore.fielddefs, False))
        wanted = [c for c in reader.connections if conv.wants(c.id)]
        for c in reader.connections:
            if not conv.wants(c.id):
                conv.count(c.id, c.msgcount)
        if not wanted:  # rosbags reads *every* connection when given none
            return
        total = sum(c.msgcount for c in wanted)
        with _progress(total, progress, path.name) as bar:
            for c, t, raw in reader.messages(connections=wanted):
                conv.feed(c.id, t, raw, reader.deserialize)
                bar.update()
            conv.end_of_messages()


def _read_salvage(path: Path, fmt: BagFormat, conv: MessageSink, progress: bool) -> list[Scan]:
    from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

    base = typestore(fmt.distro)
    store = get_typestore(Stores.EMPTY)
    store.register(dict(base.fielddefs))
    bad_defs: dict[int, str] = {}
    seen: set[int] = set()
    scans, messages = scan_bag(path, fmt.value)

    def learn(c: RawConnection) -> None:
        seen.add(c.id)
        if not c.msgdef:
            return
        try:
            if c.msgdef_format == "idl":
                types = get_types_from_idl(c.msgdef)
            else:
                types = get_types_from_msg(c.msgdef, c.msgtype)
            store.register(types)
        except Exception as exc:
            bad_defs[c.id] = f"its message definition in the bag does not parse ({exc})"

    def known(c: RawConnection) -> str | None:
        if c.id in bad_defs:
            return bad_defs[c.id]
        return _type_checker(store.fielddefs, True)(c)

    deser: Deserialize = (
        store.deserialize_ros1 if fmt.distro is Distro.ROS1 else store.deserialize_cdr
    )
    with _progress(None, progress, f"{path.name} (salvage)") as bar:
        for conn, t, raw in messages:
            if conn.id not in seen:
                learn(conn)
                conv.plan([conn], known)
            conv.feed(conn.id, t, raw, deser)
            bar.update()
        conv.end_of_messages()
    # Connections declared but never seen with a message still belong in the report.
    for scan in scans:
        for conn in scan.connections.values():
            if conn.id not in seen:
                learn(conn)
                conv.plan([conn], known)
    return scans


def read_messages(
    path: Path, fmt: BagFormat, make_sink: Callable[[], Sink], *, progress: bool = False
) -> tuple[Sink, ReadOutcome]:
    """Feed the bag's messages into a sink from ``make_sink``: read by ``AnyReader``, or — when
    that fails anywhere, or delivers fewer messages of a topic than the bag's own index claims —
    into a fresh sink by the salvage scanners, with what was lost.

    When AnyReader fell short and the scanner recovers no more, AnyReader's sink is kept.
    """
    census = take_census(path, fmt.value)
    notes: list[str] = []
    sink = make_sink()
    read_whole = True
    try:
        _read_anyreader(path, fmt, sink, progress)
    except Exception as exc:
        read_whole = False
        notes.append(
            f"AnyReader could not read it ({type(exc).__name__}: {exc}); salvaged by scanning"
        )
    else:
        claimed, _ = census.per_topic()
        short = _shortfall(claimed, sink.messages_per_topic())
        if not short:
            return sink, _outcome("AnyReader", (), notes, census, ())
        said = ", ".join(f"{t} {got} of {n}" for t, (got, n) in sorted(short.items()))
        notes.append(
            f"AnyReader delivered fewer messages than the bag's index lists ({said}): "
            "it skips records it cannot parse; read again by scanning"
        )
    salvaged = make_sink()
    scans = tuple(_read_salvage(path, fmt, salvaged, progress))
    if read_whole:
        _name_ids(census, scans)
        claimed, _ = census.per_topic()
        lost_any = sum(
            n - got for got, n in _shortfall(claimed, sink.messages_per_topic()).values()
        )
        lost_scan = sum(
            n - got for got, n in _shortfall(claimed, salvaged.messages_per_topic()).values()
        )
        if lost_scan >= lost_any:
            notes.append("the scan recovered no more; AnyReader's reading is kept")
            return sink, _outcome("AnyReader", (), notes, census, ())
    losses = tuple(loss for scan in scans for loss in scan.losses)
    return salvaged, _outcome("salvage scan", losses, notes, census, scans)


def _name_ids(census: Census, scans: Iterable[Scan]) -> None:
    """Name the census's connection ids by the scanned declarations where it could not."""
    by_path = {scan.path: scan for scan in scans}
    for f in census.files:
        scan = by_path.get(f.path)
        if scan is not None:
            for cid, conn in scan.connections.items():
                f.topics.setdefault(cid, conn.topic)


def _outcome(
    reader: str,
    losses: tuple[Loss, ...],
    notes: list[str],
    census: Census,
    scans: tuple[Scan, ...],
) -> ReadOutcome:
    _name_ids(census, scans)
    claimed, disagree = census.per_topic()
    return ReadOutcome(reader, losses, (*notes, *disagree), claimed, census.complete, census, scans)


def _shortfall(claimed: Mapping[str, int], read: Mapping[str, int]) -> dict[str, tuple[int, int]]:
    return {t: (read.get(t, 0), n) for t, n in claimed.items() if read.get(t, 0) < n}


def topic_losses(outcome: ReadOutcome, sink: MessageSink) -> dict[str, TopicLoss]:
    """Per topic, the messages the bag claims and did not reach the sink, with where they went:
    the damaged chunks that held them (their index says how many), else what is known."""
    by_path = {scan.path: scan for scan in outcome.scans}
    in_chunks: dict[str, list[tuple[int, str]]] = {}
    for f in outcome.census.files:
        scan = by_path.get(f.path)
        if scan is None:
            continue
        for chunk, counts in sorted(f.chunks.items()):
            for cid, n in sorted(counts.items()):
                missing = n - scan.delivered[(chunk, cid)]
                topic = f.topics.get(cid)
                if missing > 0 and topic is not None:
                    in_chunks.setdefault(topic, []).append(
                        (
                            missing,
                            f"{missing} of {n} in the damaged chunk at byte {chunk} of {f.path.name}",
                        )
                    )
    out: dict[str, TopicLoss] = {}
    for topic, (got, n) in sorted(_shortfall(outcome.claimed, sink.messages_per_topic()).items()):
        lost = n - got
        chunks = sorted(in_chunks.get(topic, []), key=lambda c: -c[0])
        reasons = [why for _, why in chunks[:MAX_REASONS]]
        if len(chunks) > MAX_REASONS:
            reasons.append(f"{len(chunks) - MAX_REASONS} more damaged chunk(s)")
        rest = lost - sum(m for m, _ in chunks)
        if rest > 0:
            reasons.append(
                f"{rest} the index lists that AnyReader skipped"
                if outcome.reader == "AnyReader"
                else f"{rest} not found in what could be read"
            )
        out[topic] = TopicLoss(n, lost, tuple(reasons))
    return out


def unrecovered(outcome: ReadOutcome, sink: MessageSink) -> list[Loss]:
    """Per-topic messages the bag says it had and that were not read, as loss lines."""
    return [
        Loss(
            f"topic {topic}",
            f"{loss.lost} of {loss.claimed} messages not read ({'; '.join(loss.reasons)})",
            loss.lost,
        )
        for topic, loss in topic_losses(outcome, sink).items()
    ]


def read_bag(
    path: Path | str,
    topic_map: TopicMap | None = None,
    *,
    progress: bool = False,
    identity: tuple[str, int] | None = None,
) -> BagContents:
    """Read one bag (a ``.bag`` file or a ROS 2 directory) into events and a report.

    ``identity`` is :func:`bag_identity` of the bag when the caller has just computed it.
    """
    path = Path(path)
    topic_map = topic_map or TopicMap()
    fmt = detect(path)
    bag_id, size = identity or bag_identity(path)
    conv, outcome = read_messages(
        path, fmt, lambda: Converter(topic_map, bag_id, fmt.distro), progress=progress
    )
    losses = list(outcome.losses)
    notes = list(outcome.notes)
    done = conv.finish()
    losses.extend(done.losses)
    notes.extend(done.notes)
    per_topic = topic_losses(outcome, conv)
    losses.extend(unrecovered(outcome, conv))
    if not outcome.claims_complete:
        notes.append(
            "the bag's own index is gone or damaged and only some chunks' indexes could be read: "
            "losses per topic are lower bounds (messages after a cut cannot be counted)"
        )
    types = done.event_types()
    start_ns, end_ns = conv.time_range(done)
    report = BagReport(
        path=str(path),
        format=fmt.value,
        bag_id=bag_id,
        size_bytes=size,
        reader=outcome.reader,
        topics=_topic_rows(conv, outcome.claimed, per_topic),
        skipped=_skipped_rows(conv, per_topic),
        losses=tuple(losses),
        start_ns=start_ns,
        end_ns=end_ns,
        events=sum(types.values()),
        event_types=dict(types),
        notes=tuple(notes),
        claims_complete=outcome.claims_complete,
        clock_offset_ns=done.clock_offset_ns,
        clock=done.clock,
        received_start_ns=conv.start_ns,
        received_end_ns=conv.end_ns,
        clock_pairs=done.clock_pairs if done.clock is not None else (),
    )
    return BagContents(report, done.agent, done.derived, done.poses, conv.stream)


def iter_raw(path: Path) -> Iterator[tuple[str, int, object]]:
    """Plain AnyReader iteration with deserialisation of every message (the benchmark's baseline)."""
    from rosbags.highlevel import AnyReader

    fmt = detect(path)
    with AnyReader([path], default_typestore=typestore(fmt.distro)) as reader:
        for c, t, raw in reader.messages():
            yield c.topic, t, reader.deserialize(raw, c.msgtype)
