"""How many messages a bag says it holds, per connection and per chunk, from its own records.

A reader can lose messages without failing: rosbags' MCAP reader skips records it does not
recognise inside a chunk (4 KiB of zeros inside a chunk vanish without an error), and a damaged
SQLite b-tree can return fewer rows without raising. Ingest therefore compares what it read with
what the bag itself claims, from every claim that survives:

* **ROS 2** (either storage): ``metadata.yaml``'s ``topics_with_message_count``;
* **MCAP**: the summary's Statistics (``channel_message_counts``) and its Chunk Index records,
  whose Message Index records (one per channel, after each chunk) list every message of the
  chunk; when the summary is gone, the Message Index records found by walking the data section;
* **SQLite**: ``SELECT topic_id, count(*) FROM messages``;
* **ROS 1**: the index section (Chunk Info records: per chunk, messages per connection); when it
  is gone, the Index Data records that follow each chunk.

Claims are kept per source and combined by taking the largest, so a damaged claim can only make
ingest report a loss that may not be one, never hide one. A census is ``complete`` when some
source covers the whole bag (metadata, the MCAP summary, ROS 1's index section, the SQLite
count); otherwise it only covers the chunks whose index records survived, and the losses it
gives are lower bounds. Reading the census never raises: an unreadable claim is left out.
"""

from __future__ import annotations

import mmap
import sqlite3
import struct
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from objsearch.pipeline.bags.formats import MCAP_MAGIC, ROS1_MAGIC, storage_files

MAX_RECORD = 1 << 30
Buffer = bytes | mmap.mmap


@dataclass
class FileCensus:
    """One storage file's claims, keyed by its own connection (ROS 1) or channel (MCAP) ids."""

    path: Path
    #: Connection id → topic, for the connections whose declaration the census itself read.
    topics: dict[int, str] = field(default_factory=dict)
    #: Whole-file claims, one Counter (id → messages) per source, e.g. "MCAP statistics".
    totals: dict[str, Counter[int]] = field(default_factory=dict)
    #: Per chunk (byte offset of the chunk record): id → messages its index lists.
    chunks: dict[int, Counter[int]] = field(default_factory=dict)
    complete: bool = False  # some whole-file source was read
    #: Every chunk's claims were read from records that check out (a Message Index's length is
    #: a whole number of entries; an Index Data's length is 12 bytes per entry): the per-chunk
    #: claims are then preferred to a whole-file total that disagrees (a flipped count).
    chunks_verified: bool = False
    #: Ids declared twice with different topics (a flipped id in a declaration): which topic
    #: their counts belong to is unknown, so they claim nothing.
    ambiguous: set[int] = field(default_factory=set)
    #: ROS 1 without its index section: the chunks its bag header lists (None: the header does
    #: not say, as in a bag the recorder never closed).
    expected_chunks: int | None = None

    def declare(self, cid: int, topic: str) -> None:
        """A declaration of ``cid`` as ``topic`` (a file repeats them; they must agree)."""
        known = self.topics.get(cid)
        if known is not None and known != topic:
            self.ambiguous.add(cid)
        self.topics[cid] = topic

    def chunk_sum(self) -> Counter[int]:
        total: Counter[int] = Counter()
        for c in self.chunks.values():
            total.update(c)
        return total


@dataclass(frozen=True, slots=True)
class Census:
    """A bag's claims: per storage file, plus ``metadata.yaml`` (per topic) for ROS 2."""

    files: tuple[FileCensus, ...]
    metadata: Mapping[str, int] | None

    @property
    def complete(self) -> bool:
        return self.metadata is not None or (
            bool(self.files) and all(f.complete for f in self.files)
        )

    def per_topic(self) -> tuple[dict[str, int], list[str]]:
        """Messages per topic the bag claims (largest claim of any source), and notes on
        claims that disagree. Ids no declaration names (``FileCensus.topics``) are left out."""
        claims: dict[str, dict[str, int]] = {}
        notes: list[str] = []

        def claim(source: str, topic: str, n: int) -> None:
            by_source = claims.setdefault(topic, {})
            by_source[source] = by_source.get(source, 0) + n

        if self.metadata is not None:
            for topic, n in self.metadata.items():
                claim("metadata.yaml", topic, n)
        for f in self.files:
            sources = {} if f.chunks_verified else dict(f.totals)
            if f.chunks or f.chunks_verified:  # verified and none: a bag with no messages
                sources["chunk indexes"] = f.chunk_sum()
            for source, counts in f.totals.items():
                if f.chunks_verified and counts != sources["chunk indexes"]:
                    notes.append(
                        f"{f.path.name}: its {source} disagree with its chunk indexes, "
                        "which are used"
                    )
            for cid in sorted(f.ambiguous):
                notes.append(
                    f"{f.path.name}: id {cid} is declared as different topics; its counts are "
                    "not used"
                )
            for source, counts in sources.items():
                for cid, n in counts.items():
                    name = f.topics.get(cid)
                    if name is not None and cid not in f.ambiguous:
                        claim(source, name, n)
        out: dict[str, int] = {}
        for topic, by_source in sorted(claims.items()):
            out[topic] = max(by_source.values())
            if len(set(by_source.values())) > 1:
                said = ", ".join(f"{s} {n}" for s, n in sorted(by_source.items()))
                notes.append(f"the bag's counts of {topic} disagree ({said}); the largest is used")
        return out, notes


def take_census(path: Path, fmt_value: str) -> Census:
    """Every claim the bag at ``path`` makes about its messages (never raises)."""
    take = _ros1 if fmt_value == "ros1" else _mcap
    files = []
    for f in storage_files(path):
        census = FileCensus(f)
        try:
            if fmt_value == "ros2-sqlite3":
                _sqlite(census)
            elif f.stat().st_size:
                # Mapped, not read: with an intact index only the header, index and each
                # chunk's index records are touched.
                with f.open("rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as m:
                    take(m, census)
        except (_Cut, KeyError, IndexError, ValueError, struct.error, sqlite3.Error, OSError):
            pass  # a claim that does not parse (or a file that does not open) is not a claim
        files.append(census)
    return Census(tuple(files), metadata_counts(path))


def metadata_counts(path: Path) -> dict[str, int] | None:
    """Per-topic message counts from a ROS 2 bag's metadata.yaml, if it is there and sound."""
    meta = path / "metadata.yaml"
    if not path.is_dir() or not meta.exists():
        return None
    from ruamel.yaml import YAML  # a dependency (pyproject), as rosbags' own
    from ruamel.yaml.error import YAMLError

    try:
        doc = YAML(typ="safe").load(meta.read_text(encoding="utf-8"))
        info = doc["rosbag2_bagfile_information"]
        counts: dict[str, int] = {}
        for t in info["topics_with_message_count"]:
            name, n = str(t["topic_metadata"]["name"]), int(t["message_count"])
            counts[name] = counts.get(name, 0) + n
        return counts
    except (YAMLError, OSError, ValueError, KeyError, TypeError):  # not there, or not sound
        return None


class _Cut(Exception):
    """A record runs past the bytes it has."""


class _View:
    def __init__(self, buf: Buffer, pos: int, end: int) -> None:
        if end > len(buf) or pos > end:
            raise _Cut
        self.buf, self.pos, self.end = buf, pos, end

    def take(self, n: int) -> bytes:
        if n < 0 or self.pos + n > self.end:
            raise _Cut
        self.pos += n
        return bytes(self.buf[self.pos - n : self.pos])

    def u16(self) -> int:
        return int(struct.unpack("<H", self.take(2))[0])

    def u32(self) -> int:
        return int(struct.unpack("<I", self.take(4))[0])

    def u64(self) -> int:
        return int(struct.unpack("<Q", self.take(8))[0])

    def string(self) -> str:
        return self.take(self.u32()).decode("utf-8", "replace")


# -- MCAP -------------------------------------------------------------------------------------


def _mcap_record(buf: Buffer, pos: int) -> tuple[int, _View]:
    head = _View(buf, pos, len(buf))
    op = head.take(1)[0]
    length = head.u64()
    if length > MAX_RECORD:
        raise _Cut
    return op, _View(buf, head.pos, head.pos + length)


def _mcap_message_index(rec: _View) -> tuple[int, int]:
    cid = rec.u16()
    n = rec.u32()
    if n % 16:
        raise _Cut
    rec.take(n)
    return cid, n // 16


def _mcap(buf: Buffer, census: FileCensus) -> None:
    if buf[: len(MCAP_MAGIC)] != MCAP_MAGIC:
        return
    if _mcap_summary(buf, census):
        return
    _mcap_walk(buf, census)


def _mcap_summary(buf: Buffer, census: FileCensus) -> bool:
    """The summary's channels, statistics and chunk indexes; False if there is no summary."""
    if len(buf) < 2 * len(MCAP_MAGIC) + 29 or buf[-len(MCAP_MAGIC) :] != MCAP_MAGIC:
        return False
    try:
        op, footer = _mcap_record(buf, len(buf) - len(MCAP_MAGIC) - 29)
        if op != 0x02:
            return False
        start = footer.u64()
        if not len(MCAP_MAGIC) <= start < len(buf):
            return False
        pos = start
        stats: Counter[int] | None = None
        chunk_indexes: list[tuple[int, dict[int, int]]] = []
        while pos < len(buf) - len(MCAP_MAGIC) - 29:
            op, rec = _mcap_record(buf, pos)
            pos = rec.end
            if op == 0x04:
                cid, _sid = rec.u16(), rec.u16()
                census.declare(cid, rec.string())
            elif op == 0x0B:
                rec.take(8 + 2 + 4 + 4 + 4 + 4 + 8 + 8)
                n = rec.u32()
                entries = _View(buf, rec.pos, rec.pos + n)
                stats = Counter()
                while entries.pos < entries.end:
                    cid = entries.u16()
                    stats[cid] += entries.u64()
            elif op == 0x08:
                rec.take(16)
                chunk_start = rec.u64()
                rec.u64()
                n = rec.u32()
                entries = _View(buf, rec.pos, rec.pos + n)
                offsets: dict[int, int] = {}
                while entries.pos < entries.end:
                    cid = entries.u16()
                    offsets[cid] = entries.u64()
                chunk_indexes.append((chunk_start, offsets))
    except _Cut:
        return False
    if stats is not None:
        census.totals["MCAP statistics"] = stats
    verified = bool(chunk_indexes)
    for chunk_start, offsets in chunk_indexes:
        counts: Counter[int] = Counter()
        for cid, at in offsets.items():
            try:
                op, rec = _mcap_record(buf, at)
                got, n = _mcap_message_index(rec) if op == 0x07 else (-1, 0)
            except _Cut:
                got, n = -1, 0
            if got == cid:
                counts[cid] += n
            else:
                verified = False
        census.chunks[chunk_start] = counts
    census.complete = stats is not None or bool(chunk_indexes)
    census.chunks_verified = verified
    return census.complete


def _mcap_walk(buf: Buffer, census: FileCensus) -> None:
    """The Message Index records after each chunk, walking the data section (no summary)."""
    from objsearch.pipeline.bags.salvage import _resync_mcap

    buf = bytes(buf)  # only for a damaged bag, which the salvage scan reads whole anyway
    pos = len(MCAP_MAGIC)
    chunk: int | None = None
    while pos < len(buf):
        try:
            op, rec = _mcap_record(buf, pos)
        except _Cut:
            resume = _resync_mcap(buf, pos + 1)
            if resume is None:
                return
            pos, chunk = resume, None
            continue
        if op == 0x06:
            chunk = pos
            census.chunks.setdefault(chunk, Counter())
        elif op == 0x07 and chunk is not None:
            try:
                cid, n = _mcap_message_index(rec)
            except _Cut:
                cid, n = -1, 0
            if cid >= 0:
                census.chunks[chunk][cid] += n
        elif op == 0x0F:
            return
        elif op not in (0x01, 0x03, 0x04, 0x05, 0x09, 0x0A, 0x0C):
            chunk = None
        pos = rec.end


# -- ROS 1 ------------------------------------------------------------------------------------


def _ros1_fields(buf: bytes) -> dict[str, bytes]:
    fields: dict[str, bytes] = {}
    v = _View(buf, 0, len(buf))
    while v.pos < v.end:
        name, sep, value = v.take(v.u32()).partition(b"=")
        if not sep:
            raise _Cut
        fields[name.decode("latin-1")] = value
    return fields


def _ros1_record(buf: Buffer, pos: int) -> tuple[dict[str, bytes], _View]:
    head = _View(buf, pos, len(buf))
    hlen = head.u32()
    if hlen > MAX_RECORD:
        raise _Cut
    fields = _ros1_fields(head.take(hlen))
    dlen = head.u32()
    if dlen > MAX_RECORD or "op" not in fields:
        raise _Cut
    return fields, _View(buf, head.pos, head.pos + dlen)


def _u(fields: dict[str, bytes], name: str, fmt: str) -> int:
    value = fields.get(name)
    if value is None or len(value) != struct.calcsize(fmt):
        raise _Cut
    return int(struct.unpack(fmt, value)[0])


def _ros1(buf: Buffer, census: FileCensus) -> None:
    if buf[: len(ROS1_MAGIC)] != ROS1_MAGIC:
        return
    try:
        header, rec = _ros1_record(buf, len(ROS1_MAGIC))
        index_pos = _u(header, "index_pos", "<Q")
        chunk_count = _u(header, "chunk_count", "<I")
        conn_count = _u(header, "conn_count", "<I")
        data_start = rec.end
    except _Cut:
        return
    # A bag with no messages (a split's last piece, closed before anything came) has an empty
    # index section at its very end: index_pos == its size, no chunks, no connections.
    if len(ROS1_MAGIC) < index_pos <= len(buf) and _ros1_index(buf, index_pos, census):
        census.complete = len(census.chunks) == chunk_count and len(census.topics) == conn_count
        if census.complete:
            census.totals["ROS 1 index"] = census.chunk_sum()
            census.chunks_verified = all(
                [_ros1_check_chunk(buf, pos, census) for pos in list(census.chunks)]
            )
            return
    census.chunks.clear()
    # The index section is gone or damaged. The bag header (written again when the recorder
    # closed the bag) still says where the chunks end and how many there are: if all of them
    # are there, whole, each followed by Index Data records that check out, those records
    # count every message exactly; otherwise (cut inside the chunks, or a bag never closed)
    # what the lost part held is not known.
    end = index_pos if len(ROS1_MAGIC) < index_pos <= len(buf) else len(buf)
    whole = _ros1_walk(buf, data_start, census, end)
    census.expected_chunks = chunk_count if index_pos > len(ROS1_MAGIC) else None
    if whole and end == index_pos and 0 < chunk_count == len(census.chunks):
        census.complete = census.chunks_verified = True


def _ros1_index(buf: Buffer, pos: int, census: FileCensus) -> bool:
    """Connection and Chunk Info records of the index section; False if any is unreadable."""
    try:
        while pos < len(buf):
            fields, rec = _ros1_record(buf, pos)
            pos = rec.end
            op = fields["op"]
            if op == b"\x07":
                census.declare(_u(fields, "conn", "<I"), fields["topic"].decode("utf-8", "replace"))
            elif op == b"\x06":
                chunk_pos = _u(fields, "chunk_pos", "<Q")
                counts: Counter[int] = Counter()
                for _ in range(_u(fields, "count", "<I")):
                    cid, n = rec.u32(), rec.u32()
                    counts[cid] += n
                census.chunks[chunk_pos] = counts
            else:
                return False
    except _Cut:
        return False
    return True


def _ros1_index_data(buf: Buffer, pos: int) -> Counter[int]:
    """The Index Data records from ``pos`` on, checked: 12 bytes of data per entry counted."""
    counts: Counter[int] = Counter()
    while pos < len(buf):
        fields, rec = _ros1_record(buf, pos)
        if fields["op"] != b"\x04":
            break
        n = _u(fields, "count", "<I")
        if rec.end - rec.pos != 12 * n:
            raise _Cut
        counts[_u(fields, "conn", "<I")] += n
        pos = rec.end
    return counts


def _ros1_check_chunk(buf: Buffer, pos: int, census: FileCensus) -> bool:
    """Check the index section's claims for the chunk at ``pos`` against the Index Data records
    after the chunk; where they disagree and those records check out, they are the claim."""
    try:
        fields, rec = _ros1_record(buf, pos)
        if fields["op"] != b"\x05":
            return False
        counts = _ros1_index_data(buf, rec.end)
    except _Cut:
        return False
    census.chunks[pos] = counts
    return True


def _ros1_walk(buf: Buffer, pos: int, census: FileCensus, end: int) -> bool:
    """The Index Data records after each chunk up to ``end`` (the index section is gone or
    damaged). True if every record up to ``end`` was read, every chunk is whole and each Index
    Data record checks out: then the counts are every message of those chunks."""
    from objsearch.pipeline.bags.salvage import _resync_ros1

    buf = bytes(buf[:end])  # only for a damaged bag, which the salvage scan reads whole anyway
    chunk: int | None = None
    whole = True
    while pos < len(buf):
        try:
            fields, rec = _ros1_record(buf, pos)
            op = fields["op"]
            if rec.end > len(buf):
                raise _Cut
            if op == b"\x05":
                chunk = pos
                census.chunks.setdefault(chunk, Counter())
            elif op == b"\x04" and chunk is not None:
                n = _u(fields, "count", "<I")
                if rec.end - rec.pos == 12 * n:
                    census.chunks[chunk][_u(fields, "conn", "<I")] += n
                else:
                    whole = False
            elif op in (b"\x06", b"\x07"):
                if op == b"\x07":
                    cid = _u(fields, "conn", "<I")
                    census.declare(cid, fields.get("topic", b"").decode("utf-8", "replace"))
                chunk = None
            pos = rec.end
        except _Cut:
            whole = False
            resume = _resync_ros1(buf, pos + 1)
            if resume is None:
                return False
            pos, chunk = resume, None
    return whole


# -- SQLite -----------------------------------------------------------------------------------


def _sqlite(census: FileCensus) -> None:
    db = sqlite3.connect(f"file:{census.path}?mode=ro&immutable=1", uri=True)
    try:
        for tid, name in db.execute("SELECT id, name FROM topics"):
            census.declare(int(tid), str(name))
        counts: Counter[int] = Counter()
        for tid, n in db.execute("SELECT topic_id, count(*) FROM messages GROUP BY topic_id"):
            counts[int(tid)] += int(n)
        census.totals["SQLite messages table"] = counts
        census.complete = True
    finally:
        db.close()
