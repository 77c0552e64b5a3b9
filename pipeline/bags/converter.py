"""A bag's messages → events (:class:`Converter`, one per bag), and what it made (:class:`Finished`):

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

import itertools
import json
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from objsearch.agent.catalogue import STORE
from objsearch.events import Event, InvalidEventError, deterministic_event_id
from objsearch.events.record import encode_record
from objsearch.pipeline.bags import fastdecode
from objsearch.pipeline.bags.clock import (
    STAMP_TOLERANCE_NS,
    ClockMap,
    event_times,
    fit_clock,
    iso,
    kept_pairs,
)
from objsearch.pipeline.bags.detections import detection_payload
from objsearch.pipeline.bags.posetrack import POSE_TYPE, PoseStream, PoseTrack, convert_sources
from objsearch.pipeline.bags.salvage import Loss, RawConnection
from objsearch.pipeline.bags.sink import Deserialize
from objsearch.ros.topics import ACCEPTED_TYPES, CONVERTED, Role, TopicMap
from objsearch.ros.types import Distro, typestore
from objsearch.ros.untrusted import attempt

_POSE_ROLES: Final = frozenset({Role.ODOMETRY, Role.TF, Role.TF_STATIC})


@dataclass
class TopicState:
    """One connection being read: its role, and its messages, events and rejections so far."""

    conn: RawConnection
    role: Role
    messages: int = 0
    events: int = 0
    rejected: Counter[str] = field(default_factory=Counter)


class Converter:
    """Turns a bag's messages into events; one per bag.

    Odometry and TF messages are only collected while the bag is read (:class:`PoseStream`, one
    per connection) and converted together by :meth:`finish`
    (:mod:`~objsearch.pipeline.bags.posetrack`); the others are converted as they come.
    """

    def __init__(self, topic_map: TopicMap, bag_id: str, distro: Distro) -> None:
        self.map = topic_map
        self.distro = distro
        self.stream = f"bag:{bag_id[:16]}"
        self.registry = STORE.registry
        self.topics: dict[int, TopicState] = {}
        self.skipped: dict[int, tuple[RawConnection, str]] = {}
        self.skipped_messages: Counter[int] = Counter()
        self.pose_sources: dict[int, PoseStream] = {}
        #: Other derived events, (bag time, topic, arrival, type, payload, header stamp or 0):
        #: numbered by finish() among the poses in (time, topic, arrival) order.
        self.derived: list[tuple[int, str, int, str, dict[str, Any], int]] = []
        #: Notes on derived events: per topic, those whose header stamp was not taken as their
        #: time (off the agent's clock) or was taken far from their receive time (no agent
        #: clock), and poses that look damaged (:func:`~.posetrack.suspects`).
        self.derived_notes: list[str] = []
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
                self.topics[c.id] = TopicState(c, role)
                if role in _POSE_ROLES:
                    tf = role is not Role.ODOMETRY
                    layouts = fastdecode.TF_LAYOUT if tf else fastdecode.ODOMETRY_LAYOUT
                    self.pose_sources[c.id] = PoseStream(
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
        made = attempt(lambda: self._convert(state, log_ns, raw, deserialize))
        if isinstance(made, InvalidEventError):
            state.rejected[f"invalid event: {made}"] += 1
            return
        if isinstance(made, Exception):
            state.rejected[f"{type(made).__name__}: {made}"[:200]] += 1
            return
        state.events += made
        self._accepted(log_ns, log_ns)

    def _accepted(self, first_ns: int, last_ns: int) -> None:
        self.start_ns = first_ns if self.start_ns is None else min(self.start_ns, first_ns)
        self.end_ns = last_ns if self.end_ns is None else max(self.end_ns, last_ns)

    def _convert(self, state: TopicState, log_ns: int, raw: bytes, deserialize: Deserialize) -> int:
        topic = state.conn.topic
        msg = deserialize(raw, state.conn.msgtype)
        if state.role is Role.DETECTIONS:
            payload = {
                "frame_id": msg.header.frame_id,
                "topic": topic,
                "detections": [detection_payload(d) for d in msg.detections],
            }
            stamp = getattr(msg.header, "stamp", None)
            stamp_ns = 0 if stamp is None else int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
            self.derived.append(
                (log_ns, topic, self.arrivals, "objects_detected", payload, max(stamp_ns, 0))
            )
            return 1
        if state.role is Role.EVENTS:
            return self._agent_event(msg, log_ns)
        return 0

    def end_of_messages(self) -> None:
        if self.numbered is None:
            self.numbered = self._pose_track()

    def _clock(self) -> tuple[tuple[tuple[int, int], ...], ClockMap | None]:
        """The (receive time, header stamp) pairs of the agent's events, and the clock fitted
        over them (:mod:`..clock`)."""
        pairs = kept_pairs(
            (self.received[i], self.stamps[i]) for i in self.agent if i in self.stamps
        )
        return pairs, fit_clock(pairs)

    def _pose_track(self) -> tuple[PoseTrack, list[Event]]:
        """Convert the collected odometry and TF, then time and number every derived event.

        Poses from TF only where the bag has no odometry. A derived event's time is its header
        stamp where that is on the agent's clock, else its receive time on it
        (:func:`~objsearch.pipeline.bags.clock.event_times`): what was recorded, so two
        recordings of one message give one time. Numbered in (time, topic, arrival) order,
        which is the same whichever reader (index or scan) delivered the messages.
        """
        sources = list(self.pose_sources.items())
        poses, outcomes = convert_sources([s for _, s in sources], self.map.frames)
        odometry = any(s.role is Role.ODOMETRY for s in self.topics.values())
        for (conn_id, source), outcome in zip(sources, outcomes, strict=True):
            state = self.topics[conn_id]
            # TF's poses are dropped below when odometry gives them: credit none to TF then.
            state.events += 0 if odometry and source.tf else outcome.events
            state.rejected.update(outcome.rejected)
            self.derived_notes.extend(outcome.suspects)
            if outcome.first_ns is not None and outcome.last_ns is not None:
                self._accepted(outcome.first_ns, outcome.last_ns)
        if odometry:
            poses = poses.take(~poses.from_tf)
        topics = sorted({*poses.topics, *(d[1] for d in self.derived)})
        rank = np.array([topics.index(t) for t in poses.topics] + [0], dtype=np.int64)
        n_derived = len(self.derived)
        received = np.concatenate([poses.time, np.array([d[0] for d in self.derived], np.int64)])
        stamps = np.concatenate([poses.stamp, np.array([d[5] for d in self.derived], np.int64)])
        _, clock = self._clock()
        time, took = event_times(received, stamps, clock)
        topic = np.concatenate(
            [rank[poses.topic], np.array([topics.index(d[1]) for d in self.derived], np.int64)]
        )
        arrival = np.concatenate([poses.arrival, np.array([d[2] for d in self.derived], np.int64)])
        index = np.concatenate([poses.index, np.zeros(n_derived, np.int64)])
        seq = np.empty(len(time), dtype=np.int64)
        seq[np.lexsort((index, arrival, topic, time))] = np.arange(1, len(time) + 1)
        self._note_stamps(
            [*(poses.topics[c] for c in poses.topic.tolist()), *(d[1] for d in self.derived)],
            received,
            stamps,
            time,
            took,
            clock,
        )
        n_poses = len(poses.time)
        pose_seq = seq[:n_poses]
        order = np.argsort(pose_seq)
        pose_received = poses.time[order]
        pose_time = time[:n_poses][order]
        track = PoseTrack(
            pose_seq[order],
            pose_time,
            poses.x[order],
            poses.y[order],
            poses.yaw[order],
            poses.frame[order],
            poses.topic[order],
            poses.frames,
            poses.topics,
            None if np.array_equal(pose_time, pose_received) else pose_received,
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
                        "time_ns": t,
                        "recorded_at_ns": log_ns,
                        "type": type,
                        "version": 1,
                        "task_id": None,
                        "payload": payload,
                    }
                )
                for s, t, (log_ns, _, _, type, payload, _) in zip(
                    seq[n_poses:].tolist(), time[n_poses:].tolist(), self.derived, strict=True
                )
            ),
            key=lambda e: e.seq,
        )
        return track, derived

    def _note_stamps(
        self,
        topics: Sequence[str],
        received: npt.NDArray[np.int64],
        stamps: npt.NDArray[np.int64],
        time: npt.NDArray[np.int64],
        took: npt.NDArray[np.bool_],
        clock: ClockMap | None,
    ) -> None:
        """Notes, per topic, on header stamps not taken (off the agent's clock: another clock,
        or damage) or taken far from the receive time (a bag with no agent clock)."""
        tol = STAMP_TOLERANCE_NS / 1e9
        checked = clock is not None and clock.rate_fitted
        apart = np.abs(time - received)
        none = np.zeros(len(time), dtype=bool)
        off_rows = (stamps > 0) & ~took if checked else none
        far_rows = none if checked else took & (apart > STAMP_TOLERANCE_NS)
        off = Counter(topics[i] for i in np.flatnonzero(off_rows).tolist())
        far = Counter(topics[i] for i in np.flatnonzero(far_rows).tolist())
        worst: dict[str, float] = {}
        for i in np.flatnonzero(far_rows).tolist():
            worst[topics[i]] = max(worst.get(topics[i], 0.0), float(apart[i]) / 1e9)
        for topic, n in sorted(off.items()):
            self.derived_notes.append(
                f"{n} message(s) of {topic} carry a header stamp more than {tol:g} s off the "
                "agent's clock (another clock, or damage): their events take their receive "
                "times mapped onto it"
            )
        for topic, n in sorted(far.items()):
            self.derived_notes.append(
                f"{n} message(s) of {topic} carry a header stamp more than {tol:g} s (up to "
                f"{worst[topic]:.3g} s) from their receive time, and the bag has no agent clock to "
                "check them against: their events take the stamps (recorded_at_ns keeps the "
                "receive times)"
            )

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
                f"(the simulator's 0 is {iso(offset)})"
            )
        pairs, clock = self._clock()
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
        notes += self.derived_notes
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


def _gaps(seqs: list[int]) -> list[tuple[int, int]]:
    gaps = []
    for a, b in itertools.pairwise(seqs):
        if b > a + 1:
            gaps.append((a + 1, b - 1))
    return gaps
