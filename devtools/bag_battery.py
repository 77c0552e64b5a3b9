"""The damaged-bag battery: seeded damage to copies of a bag, ingested by the CLI, accounted for.

Each :class:`Variant` is a copy of an intact bag with one kind of damage, made deterministically
from a seed: cut at an offset, bits flipped, 4 KiB zeroed inside a chunk (SQLite: inside the
database past its schema pages), ``metadata.yaml`` removed (ROS 2), or a storage file under a
wrong extension. :func:`ingest_cli` ingests a bag with ``objsearch ingest`` into a fresh lake,
in this process (``objsearch.cli.main``), and :func:`account` checks what it did against the
intact bag's ingest:

* the command exits 0 with a report, or 2 with ``objsearch: error:`` — never a traceback;
* for every topic the intact bag holds, (messages read) + (reported lost) equals the intact
  count, where a topic converted one event per message (odometry, detections, the agent's
  events) has every message read either in the lake or reported rejected. When the damaged
  bag's own index is gone its report says its claims are incomplete and gives each topic's loss
  as not known (``lost: null``); then (read + lost) may fall short, but only if the report says
  so.

Used by ``tests/pipeline/bags/test_bags_battery.py`` (a few variants per format) and
``benchmarks/damaged_bags.py`` (many).
"""

from __future__ import annotations

import contextlib
import io
import random
import shutil
import struct
import traceback
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from objsearch.pipeline.bags.census import take_census
from objsearch.pipeline.bags.formats import BagFormat, storage_files
from objsearch.ros.topics import Role, TopicMap

ZERO_BLOCK = 4096
KINDS = ("cut", "flip", "zero", "no-metadata", "extension")


@dataclass(frozen=True, slots=True)
class Variant:
    name: str
    kind: str
    make: Callable[[Path], Path]  # writes the damaged copy under a folder; returns the bag


@dataclass(frozen=True, slots=True)
class Ingested:
    """What ``objsearch ingest`` did with one bag."""

    code: int | None  # None: it raised (a traceback)
    stdout: str
    stderr: str
    report: Mapping[str, Any] | None  # the report the lake recorded of the bag
    lake_rows: Mapping[str, int]  # events in the lake per source topic


@dataclass(frozen=True, slots=True)
class Verdict:
    """One variant's outcome: ``complete``, ``loss-reported``, ``error`` (exit 2 with a
    clear message), ``traceback``, ``silent-loss`` or ``over-reported``; with details."""

    outcome: str
    problems: tuple[str, ...] = ()


def _copy(bag: Path, dest: Path) -> tuple[Path, Path]:
    """A copy of the bag under ``dest`` and the storage file in it that holds the messages."""
    dest.mkdir(parents=True, exist_ok=True)
    out = dest / bag.name
    if bag.is_dir():
        shutil.copytree(bag, out)
    else:
        shutil.copy(bag, out)
    return out, storage_files(out)[0]


def chunk_spans(bag: Path, fmt: BagFormat) -> list[tuple[int, int]]:
    """(start, end) byte offsets of the chunk records of the bag's first storage file, from its
    own index; for SQLite, the database past its first two pages."""
    data = storage_files(bag)[0]
    size = data.stat().st_size
    if fmt is BagFormat.ROS2_SQLITE3:
        return [(min(8192, size // 2), size)]
    census = take_census(bag, fmt.value).files[0]
    buf = data.read_bytes()
    spans = []
    for start in sorted(census.chunks):
        if fmt is BagFormat.ROS1:
            (hlen,) = struct.unpack_from("<I", buf, start)
            (dlen,) = struct.unpack_from("<I", buf, start + 4 + hlen)
            spans.append((start, start + 8 + hlen + dlen))
        else:
            (length,) = struct.unpack_from("<Q", buf, start + 1)
            spans.append((start, start + 9 + length))
    return spans


def variants(bag: Path, fmt: BagFormat, seed: int, per_kind: int) -> list[Variant]:
    """``per_kind`` seeded variants of each kind of damage that applies to ``fmt``."""
    rng = random.Random(f"{seed}:{fmt.value}")
    data = storage_files(bag)[0]
    size = data.stat().st_size
    spans = chunk_spans(bag, fmt)
    out: list[Variant] = []

    def cut(at: int) -> Callable[[Path], Path]:
        def make(dest: Path) -> Path:
            copy, f = _copy(bag, dest)
            with f.open("r+b") as fh:
                fh.truncate(at)
            return copy

        return make

    def flip(bits: list[tuple[int, int]]) -> Callable[[Path], Path]:
        def make(dest: Path) -> Path:
            copy, f = _copy(bag, dest)
            buf = bytearray(f.read_bytes())
            for at, bit in bits:
                buf[at] ^= 1 << bit
            f.write_bytes(bytes(buf))
            return copy

        return make

    def zero(at: int) -> Callable[[Path], Path]:
        def make(dest: Path) -> Path:
            copy, f = _copy(bag, dest)
            buf = bytearray(f.read_bytes())
            end = min(at + ZERO_BLOCK, len(buf))
            buf[at:end] = bytes(end - at)
            f.write_bytes(bytes(buf))
            return copy

        return make

    for i in range(per_kind):
        # Cuts spread over the file: one in each of per_kind equal slices.
        lo, hi = size * i // per_kind, size * (i + 1) // per_kind
        at = rng.randrange(max(lo, 16), max(hi, 17))
        out.append(Variant(f"cut@{at}", "cut", cut(at)))
    for _ in range(per_kind):
        bits = [(rng.randrange(size), rng.randrange(8)) for _ in range(rng.randrange(1, 9))]
        out.append(Variant(f"flip{[a for a, _ in bits]}", "flip", flip(bits)))
    for _ in range(per_kind):
        start, end = rng.choice(spans)
        at = rng.randrange(start, max(start + 1, end - ZERO_BLOCK // 2))
        out.append(Variant(f"zero@{at}", "zero", zero(at)))
    out.extend(_renames(bag, fmt))
    return out


def _renames(bag: Path, fmt: BagFormat) -> list[Variant]:
    def without_metadata(dest: Path) -> Path:
        copy, _ = _copy(bag, dest)
        (copy / "metadata.yaml").unlink()
        return copy

    def renamed(suffix: str) -> Callable[[Path], Path]:
        def make(dest: Path) -> Path:
            copy, f = _copy(bag, dest)
            if fmt is BagFormat.ROS1:
                return copy.rename(copy.with_suffix(suffix))
            f.rename(f.with_suffix(suffix))
            return copy

        return make

    if fmt is BagFormat.ROS1:
        return [
            Variant("named .mcap", "extension", renamed(".mcap")),
            Variant("named .bag.1", "extension", renamed(".1")),
        ]
    other = ".db3" if fmt is BagFormat.ROS2_MCAP else ".mcap"
    return [
        Variant("no metadata.yaml", "no-metadata", without_metadata),
        Variant(f"storage file named {other}", "extension", renamed(other)),
        Variant("storage file named .bin", "extension", renamed(".bin")),
    ]


def ingest_cli(bag: Path, lake: Path, main: Callable[[list[str]], int]) -> Ingested:
    """``objsearch ingest BAG --lake LAKE`` in this process through the CLI's ``main`` (the
    caller's: the pipeline does not import the CLI), its output captured."""
    from objsearch.events.lake import is_table_lake
    from objsearch.pipeline.bags.lake import FleetBagLake

    out, err = io.StringIO(), io.StringIO()
    code: int | None
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(["ingest", str(bag), "--lake", str(lake), "--no-progress"])
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
        except BaseException:
            traceback.print_exc()
            code = None
    fleet = FleetBagLake(lake) if is_table_lake(lake) else None
    docs = list(fleet.piece_docs().values()) if fleet is not None else []
    report = docs[0].get("report") if docs else None
    rows: Counter[str] = Counter()
    if fleet is not None and report is not None:
        events_topic = TopicMap().topic_for(Role.EVENTS)
        for e in fleet.events():
            if e.stream.startswith("bag:"):
                rows[str(e.payload.get("topic", "?"))] += 1
            else:
                rows[events_topic] += 1
    return Ingested(code, out.getvalue(), err.getvalue(), report, dict(rows))


def _per_topic(report: Mapping[str, Any]) -> dict[str, dict[str, int]]:
    """topic → read, lost, rejected, events, one_to_one (1 if one event per message)."""
    out: dict[str, dict[str, int]] = {}
    one_to_one = (Role.ODOMETRY.value, Role.DETECTIONS.value, Role.EVENTS.value)
    for t in report["topics"]:
        row = out.setdefault(
            t["topic"], {"read": 0, "lost": 0, "rejected": 0, "events": 0, "one_to_one": 0}
        )
        row["read"] += t["messages"]
        row["lost"] += t.get("lost") or 0  # None: not known (the report says its claims fall short)
        row["rejected"] += t["rejected"]
        row["events"] += t["events"]
        row["one_to_one"] |= int(t["role"] in one_to_one)
    for s in report["skipped"]:
        row = out.setdefault(
            s["topic"], {"read": 0, "lost": 0, "rejected": 0, "events": 0, "one_to_one": 0}
        )
        row["read"] += s["messages"]
        row["lost"] += s.get("lost") or 0
    return out


def account(intact: Ingested, damaged: Ingested) -> Verdict:
    """Check a damaged bag's ingest against the intact bag's (see the module docstring)."""
    if damaged.code is None or "Traceback" in damaged.stderr:
        return Verdict("traceback", (damaged.stderr[-2000:],))
    if damaged.code == 2 and damaged.report is None:
        if "objsearch: error:" in damaged.stderr:
            return Verdict("error")
        return Verdict("traceback", (f"exit 2 without 'objsearch: error:': {damaged.stderr}",))
    if damaged.code != 0 or damaged.report is None:
        return Verdict("traceback", (f"exit {damaged.code}: {damaged.stderr[-2000:]}",))
    assert intact.report is not None
    want = {t: r["read"] for t, r in _per_topic(intact.report).items()}
    got = _per_topic(damaged.report)
    exact = bool(damaged.report.get("claims_complete", True))
    silent: list[str] = []
    over: list[str] = []
    lost = 0
    for topic, n in sorted(want.items()):
        row = got.get(topic, {"read": 0, "lost": 0, "rejected": 0, "events": 0, "one_to_one": 0})
        lost += row["lost"]
        accounted = row["read"] + row["lost"]
        if accounted < n and exact:
            silent.append(f"{topic}: {row['read']} read + {row['lost']} lost < {n} in the bag")
        elif accounted > n:
            over.append(f"{topic}: {row['read']} read + {row['lost']} lost > {n} in the bag")
        if row["one_to_one"]:
            in_lake = damaged.lake_rows.get(topic, 0)
            if in_lake + row["rejected"] < row["read"]:
                silent.append(
                    f"{topic}: {row['read']} read but {in_lake} in the lake "
                    f"+ {row['rejected']} rejected"
                )
            if in_lake != row["events"]:
                silent.append(f"{topic}: report says {row['events']} events, lake has {in_lake}")
    if silent:
        return Verdict("silent-loss", tuple(silent))
    if over:
        return Verdict("over-reported", tuple(over))
    losses = damaged.report.get("losses", [])
    if lost or losses or not exact or any(r["rejected"] for r in got.values()):
        return Verdict("loss-reported")
    return Verdict("complete")
