"""events/log_links.py: the chain value a record was written after, solved from its own bytes,
and the witnesses that tell an edited meta.json from a damaged first record."""

from __future__ import annotations

import json
import random
import zlib
from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import EventLog
from objsearch.events.log_files import read_meta
from objsearch.events.log_links import chained_from, line_info, meta_mismatch

RUN = "00000000-0000-4000-8000-0000000000cc"


@pytest.mark.parametrize("length", [0, 1, 7, 64, 399, 5000])
def test_chained_from_solves_the_start_value_of_any_crc(length: int) -> None:
    rng = random.Random(length)
    for _ in range(20):
        body = rng.randbytes(length)
        start = rng.getrandbits(32)
        assert chained_from(body, zlib.crc32(body, start)) == start


def test_a_damaged_record_names_another_start_value() -> None:
    body = b'{"seq": 7, "payload": {"x": 12}}'
    checksum = zlib.crc32(body, 0xDEADBEEF)
    assert chained_from(body.replace(b"12", b"13"), checksum) != 0xDEADBEEF
    assert chained_from(body, checksum ^ 1) != 0xDEADBEEF


def test_line_info_never_raises_and_reads_only_a_canonical_checksum() -> None:
    for line in [b"", b"\t", b"garbage", b"{}\tzzzzzzzz", b'{"seq": "x"}\t0000000a', b"\xff\x00"]:
        info = line_info(line)
        assert info.seq is None
    assert line_info(b'{"seq": 3, "stream": "s"}\t0000000A').checksum is None  # upper case
    info = line_info(b'{"seq": 3, "stream": "s", "event_id": "e"}\t0000000a')
    assert (info.seq, info.stream, info.event_id, info.checksum) == (3, "s", "e", 10)


def _log(directory: Path, n: int = 6) -> list[bytes]:
    with EventLog.open(directory, "robot", run_id=RUN, wall_clock=lambda: 1, store=STORE) as log:
        for i in range(n):
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=i)
    return (directory / "events.log").read_bytes().splitlines()


def _edit_meta(directory: Path, **changes: str | None) -> None:
    meta = json.loads((directory / "meta.json").read_text())
    for key, value in changes.items():
        if value is None:
            del meta[key]
        else:
            meta[key] = value
    (directory / "meta.json").write_text(json.dumps(meta))


def _mismatch(directory: Path, lines: list[bytes]) -> str | None:
    data = b"".join(line + b"\n" for line in lines)
    return meta_mismatch(lambda n: data[:n], read_meta(directory))


def test_the_right_meta_json_is_never_blamed(tmp_path: Path) -> None:
    lines = _log(tmp_path)
    assert _mismatch(tmp_path, lines) is None
    damaged = bytearray(lines[0])
    damaged[damaged.index(b'"r0"') + 2] = ord("9")  # the first record edited in place
    assert _mismatch(tmp_path, [bytes(damaged), *lines[1:]]) is None
    assert _mismatch(tmp_path, [b"garbage", *lines[1:]]) is None
    assert _mismatch(tmp_path, []) is None


@pytest.mark.parametrize(
    ("changes", "says"),
    [
        ({"format": "objsearch.events/1", "run_id": None}, "the records are chained"),
        ({"run_id": "00000000-0000-4000-8000-00000000beef"}, "nor any record's id"),
        ({"stream": "robot2"}, "the records are of stream 'robot'"),
    ],
)
def test_an_edited_meta_json_is_named(
    tmp_path: Path, changes: dict[str, str | None], says: str
) -> None:
    lines = _log(tmp_path)
    _edit_meta(tmp_path, **changes)
    why = _mismatch(tmp_path, lines)
    assert why is not None and says in why and "meta.json was edited" in why
    # the first record damaged as well: the witnesses do not rest on it
    assert _mismatch(tmp_path, [b"garbage", *lines[1:]]) is not None


def test_format_2_meta_over_plain_checksums_is_named(tmp_path: Path) -> None:
    lines = _log(tmp_path)
    plain = [
        body + b"\t%08x" % zlib.crc32(body)
        for body in (line.rpartition(b"\t")[0] for line in lines)
    ]
    why = _mismatch(tmp_path, plain)
    assert why is not None and "plain checksums" in why
