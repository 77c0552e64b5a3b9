"""A battery for ``objsearch log repair``: every kind of line damage at every position of a real
log (and every edit of ``meta.json``), each run through the command as a user runs it.

For each case the command either refuses with a clear error (exit 2, ``objsearch: error: …``,
every file byte for byte unchanged), finds nothing to repair (every file unchanged), or repairs
the log; a repaired log must then verify, hold at every seq the event written there (or a
``record_quarantined`` marker), keep every record line the damaged file still held either in
``events.log`` or in a quarantine file beside it, and give the next append a seq and id no
removed record had. Anything else is a traceback, a silent change or a loss. Also counted: the
*intact* records — lines of the damaged file byte for byte as their writer wrote them — that the
repair moved out of ``events.log`` (to quarantine). Every damage here leaves a witness for them
(their chained checksums, their ids, the high-water mark), so that count must be 0.

``tests/events/test_repair.py`` runs it on a small log; ``benchmarks/log_fuzz.py`` on a large
one (``--battery-events``).
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import shutil
import tempfile
import traceback
import warnings
import zlib
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from devtools.logfuzz import STREAM, Files, _base_logs, _read_files, _write_files
from objsearch.agent.catalogue import STORE
from objsearch.events.envelope import Event
from objsearch.events.errors import EventStoreError, TornTailWarning
from objsearch.events.log import EventLog
from objsearch.events.log_files import DURABLE_FILE, LOG_FILE, META_FILE, QUARANTINE_PREFIX
from objsearch.events.log_read import read_log

#: A damage at line index ``k`` (0-based) of ``lines`` (each with its newline); ``other`` is
#: another log's lines. Returns the damaged lines, or None where it does not apply at ``k``.
LineDamage = Callable[[list[bytes], int, list[bytes]], list[bytes] | None]


def _flip(line: bytes, index: int, bit: int) -> bytes:
    b = bytearray(line)
    b[index] ^= 1 << bit
    return bytes(b)


def empty_line(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    return [*lines[:k], b"\n", *lines[k:]]


def duplicate_line(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    return [*lines[: k + 1], lines[k], *lines[k + 1 :]]


def duplicate_three_lines(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    return [*lines[: k + 3], *lines[k : k + 3], *lines[k + 3 :]]


def swap_adjacent(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes] | None:
    if k + 1 >= len(lines):
        return None
    out = list(lines)
    out[k], out[k + 1] = out[k + 1], out[k]
    return out


def swap_far(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes] | None:
    j = (k + len(lines) // 3) % len(lines)
    if abs(j - k) < 2:
        return None
    out = list(lines)
    out[k], out[j] = out[j], out[k]
    return out


def move_line_to_end(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes] | None:
    if k == len(lines) - 1:
        return None
    return [*lines[:k], *lines[k + 1 :], lines[k]]


def delete_line(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    return [*lines[:k], *lines[k + 1 :]]


def delete_three_lines(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    return [*lines[:k], *lines[k + 3 :]]


def truncate_line(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    line = lines[k]
    return [*lines[:k], line[: (len(line) - 1) // 2] + b"\n", *lines[k + 1 :]]


def cut_checksum(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    line = lines[k]
    return [*lines[:k], line[:-4] + b"\n", *lines[k + 1 :]]


def truncate_file_mid_line(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    line = lines[k]
    return [*lines[:k], line[: len(line) // 2]]


def split_line(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    line = lines[k]
    half = len(line) // 2
    return [*lines[:k], line[:half] + b"\n", line[half:], *lines[k + 1 :]]


def flip_bit_in_body(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    line = lines[k]
    index = (k * 7919 + 13) % (len(line) - 10)
    return [*lines[:k], _flip(line, index, k % 8), *lines[k + 1 :]]


def flip_bit_in_checksum(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    line = lines[k]
    return [*lines[:k], _flip(line, len(line) - 2 - k % 8, k % 3), *lines[k + 1 :]]


def flip_bit_in_tab(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    line = lines[k]
    return [*lines[:k], _flip(line, len(line) - 10, k % 8), *lines[k + 1 :]]


def flip_bit_in_newline(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    line = lines[k]
    return [*lines[:k], _flip(line, len(line) - 1, k % 8), *lines[k + 1 :]]


def byte_to_newline(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    """A byte of the record overwritten by a newline: the record split in two lines."""
    line = lines[k]
    i = 1 + (k * 104729) % (len(line) - 2)
    return [*lines[:k], line[:i] + b"\n" + line[i + 1 :], *lines[k + 1 :]]


def flip_bits_in_two_records(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes] | None:
    if k + 1 >= len(lines):
        return None
    out = list(lines)
    for j in (k, k + 1):
        out[j] = _flip(out[j], (j * 131 + 7) % (len(out[j]) - 10), j % 8)
    return out


def edit_digits_in_two_records(
    lines: list[bytes], k: int, other: list[bytes]
) -> list[bytes] | None:
    """Two records in a row edited, their checksums kept: neither may be kept as it reads."""
    if k + 1 >= len(lines):
        return None
    return [*lines[:k], _edit_digit(lines[k], k), _edit_digit(lines[k + 1], k + 1), *lines[k + 2 :]]


def insert_garbage(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    junk = [b"\x00\xff garbage \x7f\n", b'{"seq": 3, "stream": "robot"}\n', b"\t0000000a\n"]
    return [*lines[:k], junk[k % 3], *lines[k:]]


def insert_foreign_line(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    return [*lines[:k], other[k % len(other)], *lines[k:]]


def crlf_line(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    return [*lines[:k], lines[k][:-1] + b"\r\n", *lines[k + 1 :]]


def crlf_file(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes] | None:
    return [line[:-1] + b"\r\n" for line in lines] if k == 0 else None


def crlf_file_and_flip(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    damaged = flip_bit_in_body(lines, k, other)
    return [line[:-1] + b"\r\n" for line in damaged]


def _edit_digit(line: bytes, k: int) -> bytes:
    body, _, crc = line.rpartition(b"\t")
    digits = [i for i, b in enumerate(body) if 0x30 <= b <= 0x39]
    i = digits[(k * 31) % len(digits)]
    edited = bytearray(body)
    edited[i] = 0x30 + (edited[i] - 0x30 + 1 + k % 9) % 10
    return bytes(edited) + b"\t" + crc


def edit_digit(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    return [*lines[:k], _edit_digit(lines[k], k), *lines[k + 1 :]]


def edit_digit_plain_checksum(lines: list[bytes], k: int, other: list[bytes]) -> list[bytes]:
    body = _edit_digit(lines[k], k).rpartition(b"\t")[0]
    return [*lines[:k], body + b"\t%08x\n" % zlib.crc32(body), *lines[k + 1 :]]


LINE_DAMAGE: tuple[LineDamage, ...] = (
    empty_line,
    duplicate_line,
    duplicate_three_lines,
    swap_adjacent,
    swap_far,
    move_line_to_end,
    delete_line,
    delete_three_lines,
    truncate_line,
    cut_checksum,
    truncate_file_mid_line,
    split_line,
    flip_bit_in_body,
    flip_bit_in_checksum,
    flip_bit_in_tab,
    flip_bit_in_newline,
    byte_to_newline,
    flip_bits_in_two_records,
    edit_digits_in_two_records,
    insert_garbage,
    insert_foreign_line,
    crlf_line,
    crlf_file,
    crlf_file_and_flip,
    edit_digit,
    edit_digit_plain_checksum,
)


def _meta_edits(files: Files, other: Files) -> list[tuple[str, Files]]:
    """Every edit of ``meta.json`` (and two of ``durable.json``) a hand or a copy makes."""
    meta = json.loads(files[META_FILE])
    out = []

    def edited(name: str, change: Callable[[dict[str, object]], object]) -> None:
        doc = dict(meta)
        change(doc)
        out.append((name, {**files, META_FILE: json.dumps(doc).encode()}))

    def to_v1(doc: dict[str, object]) -> None:
        doc["format"] = "objsearch.events/1"
        del doc["run_id"]

    edited("format /1, run_id removed", to_v1)
    edited("format /1, run_id kept", lambda d: d.update(format="objsearch.events/1"))
    edited("run_id removed", lambda d: d.pop("run_id"))
    edited("run_id changed", lambda d: d.update(run_id="00000000-0000-4000-8000-00000000beef"))
    edited("stream changed", lambda d: d.update(stream="robot2"))
    edited("format /3", lambda d: d.update(format="objsearch.events/3"))
    out.append(("another log's meta.json", {**files, META_FILE: other[META_FILE]}))
    out.append(("meta.json cut short", {**files, META_FILE: files[META_FILE][:20]}))
    out.append(("another log's events.log", {**files, LOG_FILE: other[LOG_FILE]}))
    if DURABLE_FILE in files:
        without = dict(files)
        del without[DURABLE_FILE]
        out.append(("durable.json deleted", without))
        out.append(("durable.json cut short", {**files, DURABLE_FILE: b'{"seq": '}))
    return out


@dataclass
class BatteryReport:
    tried: int = 0
    clear_error: int = 0  # exit 2, objsearch: error: …, every file unchanged
    unchanged: int = 0  # nothing to repair, every file unchanged
    repaired: int = 0
    traceback: int = 0
    silent_change: int = 0
    loss: int = 0
    intact_moved_out: int = 0  # intact records moved out of events.log, summed over cases
    #: per damage kind: (cases, intact records moved out)
    by_kind: dict[str, list[int]] = field(default_factory=dict)
    outcomes: Counter[str] = field(default_factory=Counter)
    failures: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return (
            self.traceback == 0
            and self.silent_change == 0
            and self.loss == 0
            and self.intact_moved_out == 0
        )

    def summary(self) -> str:
        return (
            f"tried {self.tried}: clear error {self.clear_error}, unchanged {self.unchanged}, "
            f"repaired {self.repaired}, traceback {self.traceback}, silent change "
            f"{self.silent_change}, loss {self.loss}; intact records moved out "
            f"{self.intact_moved_out}"
        )


def run_repair_battery(
    events: int = 30, *, stride: int = 1, kinds: tuple[LineDamage, ...] = LINE_DAMAGE
) -> BatteryReport:
    """Every damage of ``kinds`` at every ``stride``-th line of a closed log and of one whose
    writer crashed after two thirds (acknowledged records past its mark), plus every
    ``meta.json`` edit of both, each repaired with ``objsearch log repair``."""
    from objsearch.cli import main

    report = BatteryReport()
    quiet = logging.getLogger("objsearch.events.log")
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        with tempfile.TemporaryDirectory(prefix="objsearch-repair-battery-") as tmp:
            root = Path(tmp)
            bases = _base_logs(root, events)
            other = bases["other"][0]
            other_lines = other[LOG_FILE].splitlines(keepends=True)
            cases: list[tuple[str, str, Files, str]] = []
            for victim in ("closed", "crashed"):
                files = bases[victim][0]
                lines = files[LOG_FILE].splitlines(keepends=True)
                for damage in kinds:
                    for k in range(0, len(lines), stride):
                        damaged = damage(lines, k, other_lines)
                        if damaged is not None:
                            what = f"{damage.__name__} at line {k + 1}"
                            changed = {**files, LOG_FILE: b"".join(damaged)}
                            cases.append((damage.__name__, what, changed, victim))
                for name, changed in _meta_edits(files, other):
                    cases.append(("meta_or_durable_edit", name, changed, victim))
            for n, (kind, what, files, victim) in enumerate(cases):
                directory = root / f"case-{n}"
                directory.mkdir()
                _write_files(directory, files)
                written, original = bases[victim][0][LOG_FILE], bases[victim][1]
                outcome, moved = _repair_case(main, directory, files, written, original)
                shutil.rmtree(directory)
                report.tried += 1
                tally = report.by_kind.setdefault(kind, [0, 0])
                tally[0] += 1
                tally[1] += moved
                report.intact_moved_out += moved
                head = outcome.partition(":")[0]
                report.outcomes[f"{kind}: {head}"] += 1
                attr = head.replace(" ", "_")
                setattr(report, attr, getattr(report, attr) + 1)
                if head not in ("clear error", "unchanged", "repaired"):
                    report.failures.append(f"{victim} log, {what}: {outcome}")
                if moved:
                    report.failures.append(
                        f"{victim} log, {what}: {moved} intact record(s) moved out"
                    )
    finally:
        quiet.setLevel(level)
    return report


def _repair_case(
    main: Callable[[list[str]], int],
    directory: Path,
    files: Files,
    written_log: bytes,
    original: list[Event],
) -> tuple[str, int]:
    """(outcome, intact records moved out) of ``objsearch log repair`` on one damaged log."""
    out, err = io.StringIO(), io.StringIO()
    try:
        with (
            warnings.catch_warnings(),
            contextlib.redirect_stdout(out),
            contextlib.redirect_stderr(err),
        ):
            warnings.simplefilter("ignore", TornTailWarning)
            status = main(["log", "repair", str(directory), "--no-progress"])
    except BaseException:
        return "traceback: " + traceback.format_exc(limit=4).replace("\n", " | "), 0
    now = _read_files(directory)
    if status == 2:
        if not err.getvalue().startswith("objsearch: error: "):
            return f"traceback: exit 2 without a clear error: {err.getvalue()[-300:]!r}", 0
        if now != files:
            return "silent change: refused, but changed files", 0
        return "clear error", 0
    if status != 0:
        return f"traceback: exit {status}: {err.getvalue()[-300:]!r}", 0
    if "ok: " in out.getvalue() and now != files:
        return "silent change: said clean, but changed files", 0
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", TornTailWarning)
            after = list(read_log(directory, upcast=False, store=STORE))
            with EventLog.open(directory, STREAM, store=STORE) as log:
                appended = log.append("search_failed", {"reason": "next"}, time_ns=log.last_time_ns)
    except EventStoreError as exc:
        return f"silent change: the repaired log does not read: {exc}", 0
    except Exception:
        return "traceback: " + traceback.format_exc(limit=4).replace("\n", " | "), 0
    written = {e.seq: e for e in original}
    for event in after:
        if event.type != "record_quarantined" and written.get(event.seq) != event:
            return f"silent change: seq {event.seq} is not the event written there", 0
    damaged_lines = set(files.get(LOG_FILE, b"").splitlines(keepends=True))
    record_lines = list(zip(written_log.splitlines(keepends=True), original, strict=True))
    kept_lines = set(now.get(LOG_FILE, b"").splitlines(keepends=True))
    quarantined = b"".join(data for name, data in now.items() if name.startswith(QUARANTINE_PREFIX))
    still_there = [(line, e) for line, e in record_lines if line in damaged_lines]
    lost = [e.seq for line, e in still_there if line not in kept_lines and line not in quarantined]
    if lost:
        return f"loss: seqs {lost[:5]} neither kept nor quarantined", 0
    acknowledged = _acknowledged(files)
    taken = {e.event_id for _, e in still_there} | {
        e.event_id for e in original if e.seq <= acknowledged
    }
    if appended.event_id in taken - {e.event_id for e in after}:
        return f"silent change: the next append (seq {appended.seq}) reused a removed id", 0
    moved = sum(1 for line, _ in still_there if line not in kept_lines)
    return ("repaired" if now != files else "unchanged"), moved


def _acknowledged(files: Files) -> int:
    """The seq of the high-water mark the damaged files carry (0 if none is readable)."""
    try:
        seq = json.loads(files[DURABLE_FILE])["seq"]
    except (KeyError, ValueError, TypeError):
        return 0
    return seq if type(seq) is int else 0
