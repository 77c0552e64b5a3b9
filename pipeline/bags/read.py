"""A bag of any format → events and a report (:func:`read_bag`, into :class:`BagContents`).
Pure: reads the bag, writes nothing.

``read_bag`` first reads with rosbags' ``AnyReader`` (index-driven, fast). If that fails
anywhere — a bag cut short, a damaged index or chunk — it starts again with the salvage scanners
of :mod:`objsearch.pipeline.bags.salvage` and reports what could not be read
(:mod:`~objsearch.pipeline.bags.readers`, :mod:`~objsearch.pipeline.bags.losses`). Either way
each message goes through the same conversion (:mod:`~objsearch.pipeline.bags.converter`), and
the report is built per topic (:mod:`~objsearch.pipeline.bags.report`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa

from objsearch.agent.catalogue import STORE
from objsearch.events import Event
from objsearch.events.arrow import events_to_tables
from objsearch.pipeline.bags.converter import Converter
from objsearch.pipeline.bags.formats import detect
from objsearch.pipeline.bags.identity import bag_identity
from objsearch.pipeline.bags.losses import topic_losses, unrecovered
from objsearch.pipeline.bags.posetrack import POSE_TYPE, PoseTrack
from objsearch.pipeline.bags.readers import ReadOutcome, read_messages
from objsearch.pipeline.bags.report import BagReport, skipped_rows, topic_rows
from objsearch.ros.topics import TopicMap


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
            "how many messages each topic lost is not known (messages after a cut cannot be "
            "counted); the report gives the lower bound where there is one"
        )
        notes.extend(_missing_chunks(outcome))
    types = done.event_types()
    start_ns, end_ns = conv.time_range(done)
    report = BagReport(
        path=str(path),
        format=fmt.value,
        bag_id=bag_id,
        size_bytes=size,
        reader=outcome.reader,
        topics=topic_rows(conv, outcome.claimed, per_topic, outcome.claims_complete),
        skipped=skipped_rows(conv, per_topic, outcome.claims_complete),
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


def _missing_chunks(outcome: ReadOutcome) -> list[str]:
    """What a cut ROS 1 bag's header says it held that the walk did not find."""
    notes = []
    for f in outcome.census.files:
        if f.expected_chunks is not None and f.expected_chunks > len(f.chunks):
            notes.append(
                f"{f.path.name}: its header lists {f.expected_chunks} chunks and "
                f"{len(f.chunks)} were found: messages of any topic may have been in the rest"
            )
    return notes
