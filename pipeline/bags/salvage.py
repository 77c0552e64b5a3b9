"""Reading what is left of a damaged bag, record by record, without trusting its index.

rosbags' readers need a bag's index (ROS 1), its summary and footer (MCAP) or a sound database
(SQLite): a recording cut short or a flipped byte makes them refuse the whole bag. These scanners
read the data section from the start and keep every record that parses:

* **ROS 1**: connection and message records, top-level or inside chunks; a chunk cut short or
  damaged is decompressed as far as it goes (bz2 and lz4 stream decoders; uncompressed chunks
  directly), so the messages before the damage are kept. After a broken record the scanner
  looks for the next chunk header and carries on.
* **MCAP**: schema, channel and message records, top-level or in chunks (CRC-checked when the
  writer stored a CRC); partial chunks as above; resynchronises on the next chunk.
* **SQLite** (ROS 2): the topics and definitions tables, then messages in id ranges, row by row
  where a range fails.

Each scanner records what it could not read as :class:`Loss` entries (byte ranges, chunks,
rows), so the ingest report can say exactly what was lost.
"""

from __future__ import annotations

import bz2
import sqlite3
import struct
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from objsearch.pipeline.bags.formats import MCAP_MAGIC, ROS1_MAGIC, storage_files

MAX_RECORD = 1 << 30  # a length field larger than this is damage, not data


@dataclass(frozen=True, slots=True)
class RawConnection:
    """A topic as a bag declares it: enough to build its type and route its messages."""

    id: int
    topic: str
    msgtype: str  # normalised to pkg/msg/Name
    msgdef: str
    msgdef_format: str  # "msg", "idl" or "" (none stored)


@dataclass(frozen=True, slots=True)
class Loss:
    """Something that could not be read: where, what, and how many messages if that is known."""

    where: str
    what: str
    messages: int | None = None

    def __str__(self) -> str:
        count = "" if self.messages is None else f" ({self.messages} message(s))"
        return f"{self.where}: {self.what}{count}"


@dataclass
class Scan:
    """Filled while scanning: connections as they appear, losses as they are found."""

    path: Path
    connections: dict[int, RawConnection] = field(default_factory=dict)
    losses: list[Loss] = field(default_factory=list)
    #: Messages delivered per (byte offset of the chunk record, connection id): compared with
    #: what each chunk's index lists (:mod:`~objsearch.pipeline.bags.census`) to say where
    #: messages were lost.
    delivered: Counter[tuple[int, int]] = field(default_factory=Counter)


class _Damage(Exception):
    """A record does not parse; the scanner decides how to go on."""


def normalize_msgtype(name: str) -> str:
    parts = name.split("/")
    return name if len(parts) == 3 else f"{parts[0]}/msg/{parts[-1]}"


# -- ROS 1 ------------------------------------------------------------------------------------


def _ros1_fields(buf: bytes) -> dict[str, bytes]:
    fields: dict[str, bytes] = {}
    pos = 0
    while pos < len(buf):
        if pos + 4 > len(buf):
            raise _Damage("header field length cut")
        (n,) = struct.unpack_from("<I", buf, pos)
        pos += 4
        if n > len(buf) - pos:
            raise _Damage("header field longer than its header")
        name, sep, value = buf[pos : pos + n].partition(b"=")
        if not sep:
            raise _Damage("header field without '='")
        fields[name.decode("latin-1")] = value
        pos += n
    if "op" not in fields or len(fields["op"]) != 1:
        raise _Damage("record header without an op code")
    return fields


def _ros1_record(buf: bytes, pos: int) -> tuple[dict[str, bytes], int, int, int]:
    """(header fields, data start, data length, next position) of the record at ``pos``."""
    if pos + 4 > len(buf):
        raise _Damage("record header length cut")
    (hlen,) = struct.unpack_from("<I", buf, pos)
    if hlen > MAX_RECORD or pos + 4 + hlen + 4 > len(buf):
        raise _Damage("record header runs past the data")
    fields = _ros1_fields(buf[pos + 4 : pos + 4 + hlen])
    dpos = pos + 4 + hlen
    (dlen,) = struct.unpack_from("<I", buf, dpos)
    if dlen > MAX_RECORD:
        raise _Damage("record data length implausible")
    return fields, dpos + 4, dlen, dpos + 4 + dlen


def _u32(fields: dict[str, bytes], name: str) -> int:
    value = fields.get(name)
    if value is None or len(value) != 4:
        raise _Damage(f"field {name!r} missing or malformed")
    return int(struct.unpack("<I", value)[0])


def _ros1_time(fields: dict[str, bytes]) -> int:
    value = fields.get("time")
    if value is None or len(value) != 8:
        raise _Damage("message time missing or malformed")
    sec, nsec = struct.unpack("<II", value)
    return int(sec) * 10**9 + int(nsec)


def _ros1_connection(fields: dict[str, bytes], data: bytes) -> RawConnection:
    inner = _ros1_fields(_add_op(data))
    return RawConnection(
        id=_u32(fields, "conn"),
        topic=fields.get("topic", b"").decode("utf-8", "replace"),
        msgtype=normalize_msgtype(inner.get("type", b"").decode("utf-8", "replace")),
        msgdef=inner.get("message_definition", b"").decode("utf-8", "replace"),
        msgdef_format="msg",
    )


def _add_op(data: bytes) -> bytes:
    # A connection record's data is a header without an op field; add one so it parses alike.
    return data + struct.pack("<I", 4) + b"op=\x07"


def _partial_decompress(compression: str, data: bytes) -> tuple[bytes, str | None]:
    """As much of a chunk as decompresses, and why it stopped early (None if it did not)."""
    if compression == "none":
        return data, None
    if compression == "bz2":
        dec = bz2.BZ2Decompressor()
        try:
            out = dec.decompress(data)
        except (OSError, ValueError, EOFError) as exc:
            return b"", f"bz2 data damaged ({exc})"
        return out, None if dec.eof else "bz2 stream cut short"
    if compression == "lz4":
        import lz4.frame

        ldec = lz4.frame.LZ4FrameDecompressor()
        out = b""
        step = 1 << 16
        try:
            for i in range(0, len(data), step):
                out += ldec.decompress(data[i : i + step])
        except RuntimeError as exc:
            return out, f"lz4 data damaged ({exc})"
        return out, None if ldec.eof else "lz4 stream cut short"
    return b"", f"unknown compression {compression!r}"


def _ros1_chunk_records(
    scan: Scan, data: bytes, where: str, chunk: int
) -> Iterator[tuple[RawConnection, int, bytes]]:
    pos = 0
    while pos < len(data):
        try:
            fields, dstart, _dlen, nxt = _ros1_record(data, pos)
            if nxt > len(data):
                raise _Damage("record cut short")
            op = fields["op"][0]
            body = data[dstart:nxt]
            if op == 7:
                conn = _ros1_connection(fields, body)
                scan.connections.setdefault(conn.id, conn)
            elif op == 2:
                cid = _u32(fields, "conn")
                t = _ros1_time(fields)
                conn_or_none = scan.connections.get(cid)
                if conn_or_none is None:
                    raise _Damage(f"message of undeclared connection {cid}")
                scan.delivered[(chunk, cid)] += 1
                yield conn_or_none, t, body
        except _Damage as exc:
            scan.losses.append(
                Loss(where, f"records from byte {pos} of the chunk's data on unreadable ({exc})")
            )
            return
        pos = nxt


def scan_ros1(path: Path) -> tuple[Scan, Iterator[tuple[RawConnection, int, bytes]]]:
    scan = Scan(path)
    buf = path.read_bytes()

    def gen() -> Iterator[tuple[RawConnection, int, bytes]]:
        if not buf.startswith(ROS1_MAGIC):
            scan.losses.append(Loss(str(path), "not a ROS 1 bag (magic missing): nothing read"))
            return
        _ros1_index_connections(buf, scan)
        pos = len(ROS1_MAGIC)
        chunks_ok = 0
        while pos < len(buf):
            try:
                fields, dstart, _dlen, nxt = _ros1_record(buf, pos)
                op = fields["op"][0]
                if nxt > len(buf):
                    if op != 5:
                        raise _Damage("record cut short")
                    # A chunk cut short: keep what decompresses.
                    data, why = _partial_decompress(
                        fields.get("compression", b"none").decode(), buf[dstart:]
                    )
                    scan.losses.append(
                        Loss(
                            f"{path.name} bytes {pos}–{len(buf)}",
                            f"chunk cut short by the end of the file ({why or 'truncated'}); "
                            "messages after the cut are lost",
                        )
                    )
                    yield from _ros1_chunk_records(
                        scan, data, f"{path.name} chunk at byte {pos}", pos
                    )
                    return
                body = buf[dstart:nxt]
                if op == 5:
                    compression = fields.get("compression", b"none").decode("latin-1")
                    data, why = _partial_decompress(compression, body)
                    where = f"{path.name} chunk at byte {pos}"
                    if why is not None:
                        scan.losses.append(Loss(where, f"chunk damaged: {why}"))
                    yield from _ros1_chunk_records(scan, data, where, pos)
                    chunks_ok += 1
                elif op == 7:
                    conn = _ros1_connection(fields, body)
                    scan.connections.setdefault(conn.id, conn)
                elif op == 2:
                    cid = _u32(fields, "conn")
                    conn_or_none = scan.connections.get(cid)
                    if conn_or_none is not None:
                        yield conn_or_none, _ros1_time(fields), body
                elif op not in (3, 4, 6):
                    raise _Damage(f"unknown op code {op}")
                pos = nxt
            except _Damage as exc:
                resume = _resync_ros1(buf, pos + 1)
                end = len(buf) if resume is None else resume
                scan.losses.append(
                    Loss(
                        f"{path.name} bytes {pos}–{end}",
                        f"unreadable ({exc}); "
                        + ("skipped to the next chunk" if resume else "nothing after it"),
                    )
                )
                if resume is None:
                    return
                pos = resume

    return scan, gen()


_CHUNK_OP = struct.pack("<I", 4) + b"op=\x05"


def _ros1_index_connections(buf: bytes, scan: Scan) -> None:
    """The connection records of the index section, if it is there: a writer declares each
    connection once, in the chunk of its first message, so with that chunk damaged every later
    message of the connection would be unroutable without them."""
    try:
        fields, _, _, pos = _ros1_record(buf, len(ROS1_MAGIC))
        index_pos = struct.unpack("<Q", fields.get("index_pos", b""))[0]
        pos = index_pos if len(ROS1_MAGIC) < index_pos < len(buf) else len(buf)
        while pos < len(buf):
            fields, dstart, _dlen, nxt = _ros1_record(buf, pos)
            if fields["op"] == b"\x07" and nxt <= len(buf):
                conn = _ros1_connection(fields, buf[dstart:nxt])
                scan.connections.setdefault(conn.id, conn)
            pos = nxt
    except (_Damage, struct.error):
        pass  # connections from the chunks only


def _resync_ros1(buf: bytes, start: int) -> int | None:
    """The start of the next chunk record that parses, at or after ``start``."""
    hit = buf.find(_CHUNK_OP, start)
    while hit != -1:
        for begin in range(max(start, hit - 256), hit):
            try:
                fields, _, _, _ = _ros1_record(buf, begin)
            except (_Damage, struct.error):
                continue
            if fields.get("op") == b"\x05":
                return begin
        hit = buf.find(_CHUNK_OP, hit + 1)
    return None


# -- MCAP -------------------------------------------------------------------------------------


class _Reader:
    def __init__(self, buf: bytes, pos: int = 0, end: int | None = None) -> None:
        self.buf = buf
        self.pos = pos
        self.end = len(buf) if end is None else end

    def take(self, n: int) -> bytes:
        if n < 0 or self.pos + n > self.end:
            raise _Damage("field runs past its record")
        out = self.buf[self.pos : self.pos + n]
        self.pos += n
        return out

    def u16(self) -> int:
        return int(struct.unpack("<H", self.take(2))[0])

    def u32(self) -> int:
        return int(struct.unpack("<I", self.take(4))[0])

    def u64(self) -> int:
        return int(struct.unpack("<Q", self.take(8))[0])

    def string(self) -> str:
        try:
            return self.take(self.u32()).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise _Damage(f"string not UTF-8 ({exc})") from None


def _mcap_decompress(compression: str, data: bytes, size: int) -> tuple[bytes, str | None]:
    if compression == "":
        return data, None if len(data) == size else "chunk cut short"
    if compression == "lz4":
        out, why = _partial_decompress("lz4", data)
        return out, why
    if compression == "zstd":
        try:
            from compression import zstd  # type: ignore[import-not-found,unused-ignore]
        except ImportError:
            from backports import zstd  # type: ignore[import-not-found,no-redef,unused-ignore]
        dec = zstd.ZstdDecompressor()
        try:
            out = dec.decompress(data)
        except zstd.ZstdError as exc:
            return b"", f"zstd data damaged ({exc})"
        return out, None if dec.eof else "zstd stream cut short"
    return b"", f"unknown compression {compression!r}"


def scan_mcap_file(path: Path) -> tuple[Scan, Iterator[tuple[RawConnection, int, bytes]]]:
    scan = Scan(path)
    buf = path.read_bytes()
    schemas: dict[int, tuple[str, str, str]] = {}

    def records(
        r: _Reader, where: str, top: bool, chunk: int = -1
    ) -> Iterator[tuple[RawConnection, int, bytes]]:
        while r.pos < r.end:
            start = r.pos
            try:
                if r.end - r.pos < 9:
                    raise _Damage("record header cut")
                op = r.buf[r.pos]
                r.pos += 1
                if op not in (_MCAP_TOP_OPS if top else _MCAP_CHUNK_OPS):
                    raise _Damage(
                        f"no record has op code {op:#04x}" + ("" if top else " inside a chunk")
                    )
                length = r.u64()
                if length > MAX_RECORD:
                    raise _Damage(f"record length {length} implausible")
                cut = r.pos + length > r.end
                if cut and not (top and op == 0x06):
                    raise _Damage("record cut short")
                rec = _Reader(r.buf, r.pos, min(r.pos + length, r.end))
                r.pos = rec.end
                if op == 0x03:
                    sid = rec.u16()
                    schemas[sid] = (
                        rec.string(),
                        rec.string(),
                        rec.take(rec.u32()).decode("utf-8", "replace"),
                    )
                elif op == 0x04:
                    cid, sid = rec.u16(), rec.u16()
                    topic, _encoding = rec.string(), rec.string()
                    name, enc, text = schemas.get(sid, ("", "", ""))
                    fmt = {"ros2msg": "msg", "ros2idl": "idl"}.get(enc, "")
                    if name:
                        scan.connections.setdefault(
                            cid, RawConnection(cid, topic, normalize_msgtype(name), text, fmt)
                        )
                elif op == 0x05:
                    cid = rec.u16()
                    rec.u32()
                    log_time = rec.u64()
                    rec.u64()
                    conn = scan.connections.get(cid)
                    if conn is None:
                        raise _Damage(f"message on undeclared channel {cid}")
                    scan.delivered[(chunk, cid)] += 1
                    yield conn, log_time, rec.buf[rec.pos : rec.end]
                elif op == 0x06 and top:
                    cwhere = f"{path.name} chunk at byte {start}"
                    out = _mcap_chunk(
                        rec, scan, cwhere, f"{path.name} bytes {start}–{len(buf)}", cut
                    )
                    if out is None:
                        continue
                    yield from records(_Reader(out), cwhere, top=False, chunk=start)
                    if cut:
                        return
                elif op == 0x0F and top:  # data end: the summary follows
                    return
            except _Damage as exc:
                if not top:
                    scan.losses.append(
                        Loss(where, f"records from byte {start} of the chunk on unreadable ({exc})")
                    )
                    return
                resume = _resync_mcap(buf, start + 1)
                end = len(buf) if resume is None else resume
                scan.losses.append(
                    Loss(
                        f"{path.name} bytes {start}–{end}",
                        f"unreadable ({exc}); "
                        + ("skipped to the next chunk" if resume else "nothing after it"),
                    )
                )
                if resume is None:
                    return
                r.pos = resume

    def gen() -> Iterator[tuple[RawConnection, int, bytes]]:
        if not buf.startswith(MCAP_MAGIC):
            scan.losses.append(Loss(str(path), "not an MCAP file (magic missing): nothing read"))
            return
        yield from records(_Reader(buf, len(MCAP_MAGIC)), path.name, top=True)

    return scan, gen()


def _mcap_chunk(rec: _Reader, scan: Scan, where: str, to_end: str, cut: bool) -> bytes | None:
    """A chunk record's records, decompressed (what could be), its damage noted in ``scan``;
    None when its CRC proves them damaged (they are dropped). ``to_end``: the bytes from it to
    the end of the file, named for a chunk ``cut`` short."""
    rec.u64()
    rec.u64()
    size = rec.u64()
    crc = rec.u32()
    compression = rec.string()
    clen = rec.u64()
    data = rec.buf[rec.pos : min(rec.pos + clen, rec.end)]
    out, why = _mcap_decompress(compression, data, size)
    if cut:
        scan.losses.append(
            Loss(
                to_end,
                "chunk cut short by the end of the file; messages after the cut are lost",
            )
        )
    elif why is not None:
        scan.losses.append(Loss(where, f"chunk damaged: {why}"))
    elif crc:
        from zlib import crc32

        if crc32(out) != crc:
            scan.losses.append(Loss(where, "chunk CRC mismatch: its messages are dropped"))
            return None
    return out


# Record op codes of the MCAP spec: 0x01–0x10 at the top level (0x80 and up are for users); a
# chunk holds only schemas, channels and messages. Any other op byte is damage (rosbags' reader
# skips it, and the messages it hides, silently).
_MCAP_TOP_OPS = frozenset([*range(0x01, 0x11), *range(0x80, 0x100)])
_MCAP_CHUNK_OPS = frozenset({0x03, 0x04, 0x05})


def _resync_mcap(buf: bytes, start: int) -> int | None:
    """The next plausible chunk record (op 0x06, sane lengths, known compression)."""
    pos = buf.find(b"\x06", start)
    while pos != -1 and pos + 50 <= len(buf):
        try:
            r = _Reader(buf, pos + 1)
            length = r.u64()
            r.u64()
            r.u64()
            size = r.u64()
            r.u32()
            compression = r.string()
            clen = r.u64()
            if (
                compression in ("", "lz4", "zstd")
                and length < MAX_RECORD
                and size < MAX_RECORD
                and clen <= length
            ):
                return pos
        except _Damage:
            pass
        pos = buf.find(b"\x06", pos + 1)
    return None


# -- SQLite -----------------------------------------------------------------------------------

ROWS_PER_QUERY = 512


def _readable_copy(path: Path, scan: Scan) -> Path | None:
    """A copy SQLite will open, if ``path`` was cut short: padded to whole pages, with the
    header's page count made to match (else SQLite calls the whole file malformed)."""
    data = bytearray(path.read_bytes())
    if len(data) < 100 or not data.startswith(b"SQLite format 3\x00"):
        return None
    (page,) = struct.unpack(">H", data[16:18])
    page = 65536 if page == 1 else page
    (pages,) = struct.unpack(">I", data[28:32])
    if page < 512 or pages * page == len(data):
        return None
    scan.losses.append(
        Loss(
            f"{path.name} bytes {len(data)}–{pages * page}",
            f"file cut short: {pages * page - len(data)} byte(s) of {pages} page(s) missing",
        )
    )
    data += bytes((-len(data)) % page)
    data[28:32] = struct.pack(">I", len(data) // page)
    import tempfile

    fd, name = tempfile.mkstemp(suffix=".db3", prefix="objsearch-salvage-")
    with open(fd, "wb") as fh:
        fh.write(data)
    return Path(name)


def scan_sqlite_file(path: Path) -> tuple[Scan, Iterator[tuple[RawConnection, int, bytes]]]:
    scan = Scan(path)

    def gen() -> Iterator[tuple[RawConnection, int, bytes]]:
        copy = _readable_copy(path, scan)
        try:
            yield from _scan_sqlite(copy or path)
        finally:
            if copy is not None:
                copy.unlink()

    def _scan_sqlite(db_path: Path) -> Iterator[tuple[RawConnection, int, bytes]]:
        try:
            db = sqlite3.connect(f"file:{db_path}?mode=ro&immutable=1", uri=True)
        except sqlite3.Error as exc:
            scan.losses.append(Loss(path.name, f"SQLite cannot open it ({exc}): nothing read"))
            return
        try:
            defs: dict[str, tuple[str, str]] = {}
            try:
                for name, enc, text in db.execute(
                    "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions"
                ):
                    defs[name] = ({"ros2msg": "msg", "ros2idl": "idl"}.get(enc, ""), text)
            except sqlite3.Error as exc:
                scan.losses.append(Loss(f"{path.name} message_definitions", f"unreadable ({exc})"))
            try:
                topics = list(db.execute("SELECT id, name, type FROM topics"))
            except sqlite3.Error as exc:
                scan.losses.append(
                    Loss(f"{path.name} topics", f"unreadable ({exc}): no message can be routed")
                )
                return
            for tid, name, typ in topics:
                fmt, text = defs.get(typ, ("", ""))
                scan.connections[tid] = RawConnection(tid, name, normalize_msgtype(typ), text, fmt)
            try:
                (top,) = db.execute("SELECT max(id) FROM messages").fetchone()
            except sqlite3.Error:
                top = None
            if top is None:
                top = _probe_max_id(db)
            lo = 1
            while lo <= top:
                hi = lo + ROWS_PER_QUERY - 1
                try:
                    rows = list(
                        db.execute(
                            "SELECT id, topic_id, timestamp, data FROM messages "
                            "WHERE id BETWEEN ? AND ? ORDER BY id",
                            (lo, hi),
                        )
                    )
                except sqlite3.Error:
                    rows = list(_rows_one_by_one(db, scan, path, lo, hi))
                for _, tid, t, data in rows:
                    conn = scan.connections.get(tid)
                    if conn is None:
                        scan.losses.append(
                            Loss(f"{path.name} messages", f"row of unknown topic id {tid}", 1)
                        )
                        continue
                    yield conn, int(t), bytes(data)
                lo = hi + 1
        finally:
            db.close()

    return scan, gen()


def _probe_max_id(db: sqlite3.Connection) -> int:
    # max(id) failed: the b-tree's right edge is damaged. Row ids are dense from 1 in bags we
    # know; walk up in steps until rows stop appearing for a while.
    top, probe, misses = 0, 1, 0
    while misses < 8:
        try:
            row = db.execute(
                "SELECT id FROM messages WHERE id >= ? ORDER BY id LIMIT 1", (probe,)
            ).fetchone()
        except sqlite3.Error:
            row = None
        if row is None:
            misses += 1
        else:
            top = max(top, int(row[0]))
            misses = 0
        probe += ROWS_PER_QUERY
    return top


def _rows_one_by_one(
    db: sqlite3.Connection, scan: Scan, path: Path, lo: int, hi: int
) -> Iterator[tuple[int, int, int, bytes]]:
    bad: list[int] = []
    for rid in range(lo, hi + 1):
        try:
            row = db.execute(
                "SELECT id, topic_id, timestamp, data FROM messages WHERE id = ?", (rid,)
            ).fetchone()
        except sqlite3.Error:
            bad.append(rid)
            continue
        if row is not None:
            yield row
    if bad:
        scan.losses.append(
            Loss(
                f"{path.name} messages row ids {bad[0]}–{bad[-1]}",
                f"{len(bad)} row id(s) unreadable (database damaged; ids past the last "
                "message may never have existed, so the per-topic counts below are the loss)",
            )
        )


def scan_bag(
    path: Path, fmt_value: str
) -> tuple[list[Scan], Iterator[tuple[RawConnection, int, bytes]]]:
    """Scanners for every storage file of the bag, chained in file order."""
    scanner = {"ros1": scan_ros1, "ros2-mcap": scan_mcap_file, "ros2-sqlite3": scan_sqlite_file}[
        fmt_value
    ]
    scans_and_gens = [scanner(f) for f in storage_files(path)]
    scans = [s for s, _ in scans_and_gens]

    def chain() -> Iterator[tuple[RawConnection, int, bytes]]:
        for _, g in scans_and_gens:
            yield from g

    return scans, chain()
