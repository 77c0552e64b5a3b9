"""Which recording session a bag belongs to, and how its pieces become one run.

A session is one run of the agent. Real robots record it in pieces (``rosbag record --split``,
``ros2 bag record --max-bag-duration``, several storage files), and the same session may be
ingested in more than one format. Every piece that carries agent events names its session
through them: the agent's events have ids ``uuid5(run id/seq)``
(:func:`~objsearch.events.envelope.deterministic_event_id`), and a run id derived from the run's
spec (:func:`objsearch.agent.session.derived_run_id`, what ``record`` and seeded runs use) can be
recomputed from the ``run_started`` event. So:

* a piece holding ``run_started`` proves its run id (``run_started.params.run_id``, checked
  against the event's id);
* any other piece is matched against the run ids the lake already knows (bag sessions and
  compacted agent logs alike): one event id that equals ``uuid5(candidate/seq)`` proves it
  belongs;
* pieces whose run id nothing proves (the recorder started after the agent, so no piece holds
  ``run_started``) are one recording when their agent events are one stream's: a common seq with
  the same event id, or consecutive seqs (:func:`continues`) with time running on. Such a session
  is a provisional run named by its lowest event (:func:`provisional_run_name`), renamed as earlier
  pieces arrive and absorbed when its run id becomes known;
* a piece with no agent events (a split's stretch of odometry alone) belongs to the session of
  the same robot whose receive times enclose its own.

Merging keeps the agent's events once (by id) and the derived ones (poses, detections) once by
what was recorded — content and time, which is the message's header stamp wherever that is on
the agent's clock (:func:`~objsearch.pipeline.bags.clock.event_times`), never the receive time
of one recorder — puts the derived ones on the session's clock (:mod:`~objsearch.pipeline.bags.clock`,
fitted over all its pieces) and numbers them again in the session's own stream in (time, type,
seq) order, so the run is the same whatever order the pieces came in.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import uuid
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

import pyarrow as pa
import pyarrow.compute as pc

from objsearch.events import Event
from objsearch.events.envelope import deterministic_event_id
from objsearch.pipeline.bags.clock import ClockMap, on_receive_clock
from objsearch.ros.topics import TopicMap

if TYPE_CHECKING:
    import polars as pl

#: Bump when a change to the conversion changes what a bag gives: bags ingested by an older
#: converter are read again on the next ingest.
CONVERTER_VERSION: Final = 3
DERIVED_PREFIX: Final = "bag:"
#: uuid.uuid5(uuid.NAMESPACE_URL, "urn:objsearch:runs"), as objsearch.agent.session defines it
#: (not imported: the pipeline must not load the agent).
RUN_ID_NAMESPACE: Final = uuid.uuid5(uuid.NAMESPACE_URL, "urn:objsearch:runs")
_ENVELOPE_IDS: Final = ("event_id", "stream", "seq")


def converter_key(topic_map: TopicMap) -> str:
    """What decides how a bag converts: the topic map (topics and frames) and this version."""
    doc = {
        "version": CONVERTER_VERSION,
        "topics": {t: r.value for t, r in sorted(topic_map.topics.items())},
        "frames": repr(topic_map.frames),
    }
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"))
    return f"v{CONVERTER_VERSION}:" + hashlib.sha256(text.encode()).hexdigest()[:16]


@dataclass(frozen=True, slots=True)
class FirstEvent:
    """The lowest-seq agent event of a piece: what places a provisional piece later."""

    stream: str
    seq: int
    event_id: str


def first_event(agent: Sequence[Event]) -> FirstEvent | None:
    if not agent:
        return None
    e = min(agent, key=lambda e: (e.stream, e.seq))
    return FirstEvent(e.stream, e.seq, e.event_id)


def belongs(run_id: str, first: FirstEvent) -> bool:
    return deterministic_event_id(run_id, first.seq) == first.event_id


def run_id_of(agent: Sequence[Event], candidates: Iterable[str]) -> str | None:
    """The agent run these events prove they belong to, or None (see the module docstring)."""
    for e in agent:
        if e.type == "run_started":
            # The agent records its log's run id in run_started's params; the event's own id
            # (uuid5(run id, seq)) proves it.
            params = e.payload.get("params")
            rid = params.get("run_id") if isinstance(params, Mapping) else None
            if isinstance(rid, str) and deterministic_event_id(rid, e.seq) == e.event_id:
                return rid
    first = first_event(agent)
    if first is None:
        return None
    return next((c for c in candidates if belongs(c, first)), None)


def session_run_name(run_id: str) -> str:
    """The lake run of an identified session: ``bag-`` and the run id's first 16 hex digits."""
    return "bag-" + run_id.replace("-", "")[:16]


def provisional_run_name(first: FirstEvent) -> str:
    """The lake run of a session whose run id is not known yet: ``bag-`` and the first 16 hex
    digits of its lowest agent event's id (the same whichever of its pieces came first)."""
    return "bag-" + first.event_id.replace("-", "")[:16]


@dataclass(frozen=True, slots=True)
class Span:
    """The agent events of one stream in a piece or session: first and last seq and time."""

    stream: str
    first_seq: int
    last_seq: int
    first_time_ns: int
    last_time_ns: int

    def to_doc(self) -> list[int]:
        return [self.first_seq, self.last_seq, self.first_time_ns, self.last_time_ns]

    @staticmethod
    def from_doc(stream: str, doc: object) -> Span | None:
        if not isinstance(doc, list) or len(doc) != 4:
            return None
        try:
            return Span(stream, *(int(v) for v in doc))
        except (TypeError, ValueError):
            return None


def agent_rows(tables: Mapping[str, pa.Table]) -> pl.DataFrame:
    """``stream, seq, event_id, time_ns`` of the agent's events in a set of tables."""
    import polars as pl  # on first use: `lake add`'s check of bag runs imports this module

    columns = ["stream", "seq", "event_id", "time_ns"]
    frames = []
    for table in tables.values():
        df = pl.from_arrow(table.select(columns))
        assert isinstance(df, pl.DataFrame)
        frames.append(df.filter(~pl.col("stream").str.starts_with(DERIVED_PREFIX)))
    if not frames:
        return pl.DataFrame(schema={"stream": pl.String, "seq": pl.Int64, "event_id": pl.String})
    return pl.concat(frames, how="vertical_relaxed").sort("stream", "seq")


def spans_of(rows: pl.DataFrame) -> dict[str, Span]:
    spans = {}
    for (stream,), df in rows.group_by("stream", maintain_order=True):
        first, last = df.row(0, named=True), df.row(-1, named=True)
        spans[str(stream)] = Span(
            str(stream), first["seq"], last["seq"], first["time_ns"], last["time_ns"]
        )
    return spans


def continues(a: Span, b: Span) -> bool:
    """One stream's events going on from one piece into the other: consecutive seqs, and time
    not running backwards across the boundary."""
    if a.stream != b.stream:
        return False
    return (b.first_seq == a.last_seq + 1 and b.first_time_ns >= a.last_time_ns) or (
        a.first_seq == b.last_seq + 1 and a.first_time_ns >= b.last_time_ns
    )


def overlaps(a: Span, b: Span) -> bool:
    return a.stream == b.stream and a.first_seq <= b.last_seq and b.first_seq <= a.last_seq


def same_ids(a: pl.DataFrame, b: pl.DataFrame) -> bool | None:
    """Whether two sets of agent rows are one run's where they share (stream, seq): True if
    every shared seq has the same event id, False if one differs, None if none is shared."""
    import polars as pl  # on first use: `lake add`'s check of bag runs imports this module

    shared = a.select("stream", "seq", "event_id").join(
        b.select("stream", "seq", pl.col("event_id").alias("other")), on=["stream", "seq"]
    )
    if shared.is_empty():
        return None
    return bool((shared["event_id"] == shared["other"]).all())


def merge_tables(
    parts: Sequence[Mapping[str, pa.Table]],
    stream: str,
    drop: Sequence[tuple[int, int]] = (),
    clock: ClockMap | None = None,
    clock_range: tuple[int, int] | None = None,
    part_clocks: Sequence[ClockMap | None] | None = None,
) -> dict[str, pa.Table]:
    """One session's tables from several pieces' (earlier pieces win ties).

    ``drop`` are receive-time ranges whose derived rows are removed first from every part but
    the last (a piece read again with another topic map or converter replaces its rows).
    ``clock`` puts the derived rows received within ``clock_range`` whose time is their receive
    time on the session's clock: ``time_ns`` = its map of ``recorded_at_ns``. ``part_clocks``
    (one per part: the clock its rows were put on, None for none) tells those rows from rows
    timed by their header stamp, which keep it (:func:`~.clock.on_receive_clock`); without it
    every derived row in the range is mapped. Rows of a recording whose receive times are
    already the agent's clock lie outside the range and are left alone. Derived rows are then
    kept once by content and time, whichever recorder received them when.
    """
    import numpy as np
    import polars as pl  # on first use: `lake add`'s check of bag runs imports this module

    types = sorted({t for p in parts for t in p})
    merged: dict[str, pl.DataFrame] = {}
    for event_type in types:
        frames = []
        for i, part in enumerate(parts):
            if event_type not in part:
                continue
            df = pl.from_arrow(part[event_type])
            assert isinstance(df, pl.DataFrame)
            derived = pl.col("stream").str.starts_with(DERIVED_PREFIX)
            if drop and i < len(parts) - 1:
                inside = pl.any_horizontal(
                    [pl.col("recorded_at_ns").is_between(a, b) for a, b in drop]
                )
                df = df.filter(~(derived & inside))
            if clock is not None and clock_range is not None and df.height:
                received = df["recorded_at_ns"].to_numpy().astype(np.int64)
                time = df["time_ns"].to_numpy().astype(np.int64)
                # Rows timed by their header stamps keep them (what was recorded: two
                # recordings of one message give one time); rows timed by their receive time
                # (on the clock their part put them on) take the session's map of it.
                part_clock = part_clocks[i] if part_clocks is not None else None
                on_clock = (
                    df.select(derived).to_series().to_numpy()
                    & ((received >= clock_range[0]) & (received <= clock_range[1]))
                    & (on_receive_clock(time, received, part_clock) | (part_clocks is None))
                )
                times = np.where(on_clock, clock.apply(received), time)
                df = df.with_columns(pl.Series("time_ns", times, dtype=df.schema["time_ns"]))
            frames.append(df)
        merged[event_type] = pl.concat(frames, how="vertical_relaxed")
    agent_frames: dict[str, pl.DataFrame] = {}
    derived_frames: dict[str, pl.DataFrame] = {}
    for event_type, df in merged.items():
        is_derived = pl.col("stream").str.starts_with(DERIVED_PREFIX)
        agent_frames[event_type] = df.filter(~is_derived).unique(
            subset=["event_id"], keep="first", maintain_order=True
        )
        # What was recorded: the message's content and its time (its header stamp, where on
        # the session's clock), not when each recorder received it (recorded_at_ns).
        content = [c for c in df.columns if c not in (*_ENVELOPE_IDS, "recorded_at_ns")]
        # A message recorded twice keeps the receive time (recorded_at_ns) of the recording
        # ingested first (earlier parts come first).
        derived_frames[event_type] = df.filter(is_derived).unique(
            subset=content, keep="first", maintain_order=True
        )
    # Number the derived rows again, across types, in the session's stream.
    keys = [
        df.select("time_ns", "seq").with_columns(
            pl.lit(event_type).alias("type"), pl.int_range(pl.len()).alias("row")
        )
        for event_type, df in derived_frames.items()
        if df.height
    ]
    new_seq: dict[str, pl.Series] = {}
    if keys:
        order = pl.concat(keys).sort(["time_ns", "type", "seq"], maintain_order=True)
        order = order.with_columns(pl.int_range(1, pl.len() + 1, dtype=pl.Int64).alias("new"))
        for event_type in derived_frames:
            rows = order.filter(pl.col("type") == event_type).sort("row")
            new_seq[event_type] = rows["new"]
    out: dict[str, pa.Table] = {}
    for event_type in types:
        renumbered = derived_frames[event_type]
        if renumbered.height:
            seqs = new_seq[event_type]
            ids = [deterministic_event_id(stream, s) for s in seqs.to_list()]
            renumbered = renumbered.with_columns(
                pl.Series("seq", seqs, dtype=renumbered.schema["seq"]),
                pl.lit(stream).alias("stream"),
                pl.Series("event_id", ids),
            ).sort("seq")
        table = pl.concat([agent_frames[event_type], renumbered], how="vertical_relaxed").to_arrow()
        schema = parts_schema(parts, event_type)
        out[event_type] = table.select(schema.names).cast(schema)
    return out


def parts_schema(parts: Sequence[Mapping[str, pa.Table]], event_type: str) -> pa.Schema:
    return next(p[event_type].schema for p in parts if event_type in p)


def rows_of(tables: Mapping[str, pa.Table], agent: bool) -> int:
    """Agent (or derived) rows in a set of tables."""
    n = 0
    for table in tables.values():
        derived = pc.starts_with(table["stream"], DERIVED_PREFIX)
        n += pc.sum(pc.invert(derived) if agent else derived).as_py() or 0
    return n


def disagreements(parts: Sequence[Mapping[str, pa.Table]]) -> dict[str, int]:
    """Per derived event type, the messages two parts (two recordings of one session) hold
    differently: (topic, time) keys at which each of two parts has a row the other lacks. Rows
    timed by their header stamps share their key across recordings, so a message damaged in one
    of them (a flipped bit) shows up here; a message one recorder missed does not (its rows are
    a subset of the other's)."""
    import polars as pl  # on first use: `lake add`'s check of bag runs imports this module

    out: dict[str, int] = {}
    for event_type in sorted({t for p in parts for t in p}):
        frames = []
        for i, part in enumerate(parts):
            table = part.get(event_type)
            if table is None or "topic" not in table.column_names:
                continue
            df = pl.from_arrow(table)
            assert isinstance(df, pl.DataFrame)
            df = df.filter(pl.col("stream").str.starts_with(DERIVED_PREFIX))
            content = [c for c in df.columns if c not in (*_ENVELOPE_IDS, "recorded_at_ns")]
            frames.append(
                df.select(
                    pl.lit(i).alias("part"),
                    "topic",
                    "time_ns",
                    pl.struct(content).hash().alias("h"),
                )
            )
        if len(frames) < 2:
            continue
        keys = ["topic", "time_ns"]
        rows = pl.concat(frames)
        shared = (
            rows.group_by(keys).agg(pl.col("part").n_unique().alias("n")).filter(pl.col("n") > 1)
        )
        if shared.is_empty():
            continue
        sets = rows.join(shared.select(keys), on=keys).group_by([*keys, "part"]).agg(pl.col("h"))
        differ = 0
        for _, group in sets.group_by(keys):
            held = [set(h) for h in group["h"].to_list()]
            if any(not (a <= b or b <= a) for a, b in itertools.combinations(held, 2)):
                differ += 1
        if differ:
            out[event_type] = differ
    return out
