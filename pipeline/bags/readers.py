"""A bag's messages into a :class:`~objsearch.pipeline.bags.sink.MessageSink`
(:func:`read_messages`): rosbags' ``AnyReader`` (index-driven, fast), else — when that fails
anywhere or falls short of the bag's own index — the salvage scanners of
:mod:`objsearch.pipeline.bags.salvage`, with what the bag claims (:class:`ReadOutcome`); and
:func:`iter_raw`, plain ``AnyReader`` iteration.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from objsearch.pipeline.bags.census import Census, take_census
from objsearch.pipeline.bags.errors import BagError
from objsearch.pipeline.bags.formats import BagFormat, detect
from objsearch.pipeline.bags.salvage import Loss, RawConnection, Scan, scan_bag
from objsearch.pipeline.bags.sink import Deserialize, MessageSink
from objsearch.ros.types import Distro, typestore
from objsearch.ros.untrusted import attempt

PROGRESS_MIN_MESSAGES = 20_000


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
    from rosbags.typesys import (
        Stores,
        TypesysError,
        get_types_from_idl,
        get_types_from_msg,
        get_typestore,
    )

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
        except TypesysError as exc:
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
    failed = attempt(lambda: _read_anyreader(path, fmt, sink, progress))
    if isinstance(failed, Exception):  # rosbags' reader on damaged bytes: scan instead
        read_whole = False
        notes.append(
            f"AnyReader could not read it ({type(failed).__name__}: {failed}); salvaged by scanning"
        )
    else:
        claimed, _ = census.per_topic()
        short = shortfall(claimed, sink.messages_per_topic())
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
        lost_any = sum(n - got for got, n in shortfall(claimed, sink.messages_per_topic()).values())
        lost_scan = sum(
            n - got for got, n in shortfall(claimed, salvaged.messages_per_topic()).values()
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


def shortfall(claimed: Mapping[str, int], read: Mapping[str, int]) -> dict[str, tuple[int, int]]:
    """The topics with fewer messages read than claimed: topic → (read, claimed)."""
    return {t: (read.get(t, 0), n) for t, n in claimed.items() if read.get(t, 0) < n}


def iter_raw(path: Path) -> Iterator[tuple[str, int, object]]:
    """Plain AnyReader iteration with deserialisation of every message (the benchmark's baseline)."""
    from rosbags.highlevel import AnyReader

    fmt = detect(path)
    with AnyReader([path], default_typestore=typestore(fmt.distro)) as reader:
        for c, t, raw in reader.messages():
            yield c.topic, t, reader.deserialize(raw, c.msgtype)
