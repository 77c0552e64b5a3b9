"""A seeded fuzzer for the event log: damage a real log every way a disk, an editor, git or a
careless copy can, then open it as the next writer would and hold the store to its promise.

For every case the writer either refuses (an :class:`EventStoreError` naming the problem, every
file byte for byte unchanged, nothing kept aside) or opens the log with every acknowledged
event exactly as written; the only bytes it may take out of ``events.log`` are an unterminated
fragment past the durable high-water mark, and those it keeps in a quarantine file. Anything
else — a traceback, a changed event, a lost byte — is a failure, reported with the case that
caused it. ``tests/events/test_log_fuzz.py`` runs a few thousand cases; ``benchmarks/log_fuzz.py``
runs more and prints the counts.
"""

from __future__ import annotations

import json
import logging
import os
import random
import shutil
import tempfile
import traceback
import warnings
import zlib
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from objsearch.agent.catalogue import STORE
from objsearch.events.envelope import Event
from objsearch.events.errors import EventStoreError, TornTailWarning
from objsearch.events.log import EventLog
from objsearch.events.log_files import DURABLE_FILE, LOG_FILE, META_FILE, QUARANTINE_PREFIX
from objsearch.events.log_read import read_log

STREAM = "robot"
Files = dict[str, bytes]
Mutation = Callable[[random.Random, Files, Files], str]


@dataclass
class FuzzReport:
    tried: int = 0
    refused: int = 0  # exit 2: an error naming the problem, nothing changed
    unchanged: int = 0  # opened with every acknowledged event as written (damage was harmless)
    torn_kept: int = 0  # an unterminated fragment past the high-water mark, cut and kept aside
    # Undetectable by design (docs/events.md): a log cut at a record boundary past its durable
    # high-water mark is a clean prefix; records past the mark re-chained by someone who knows
    # the format are a forgery, not damage.
    clean_prefix: int = 0
    forged: int = 0
    traceback: int = 0
    silent_change: int = 0
    by_mutation: Counter[str] = field(default_factory=Counter)
    failures: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.traceback == 0 and self.silent_change == 0

    def summary(self) -> str:
        return (
            f"tried {self.tried}: refused with a clear error {self.refused}, opened unchanged "
            f"{self.unchanged}, torn fragment cut and kept {self.torn_kept}, clean prefix past "
            f"the high-water mark {self.clean_prefix}, forged past it {self.forged}, traceback "
            f"{self.traceback}, silent change {self.silent_change}"
        )


def _make_log(directory: Path, run_id: str, n: int, *, crash_after: int | None = None) -> None:
    """A log of ``n`` search events; with ``crash_after``, its writer died after that many
    were closed cleanly (the rest acknowledged, but past the high-water mark)."""
    reasons = ["no viewpoint", "blocked", "caf\u00e9 \u2028 sep", "timeout"]

    def write(log: EventLog, first: int, last: int) -> None:
        for i in range(first, last):
            task = f"task-{i // 3:05d}"
            if i % 3 == 0:
                pose = {"x": 0.25 * i, "y": -1.5, "yaw": 0.5}
                payload = {
                    "target": "Cup",
                    "start": "kitchen-1",
                    "pose": pose,
                    "scene": i,
                    "clock": None,
                }
                log.append("task_started", payload, time_ns=10 * i, task_id=task)
            elif i % 3 == 1:
                log.append(
                    "search_failed", {"reason": reasons[i % 4]}, time_ns=10 * i, task_id=task
                )
            else:
                done = {"target": "Cup", "success": False, "path_length": 1.25 * i}
                log.append("task_ended", done, time_ns=10 * i, task_id=task)

    clean = n if crash_after is None else crash_after
    with EventLog.open(directory, STREAM, run_id=run_id, wall_clock=lambda: 7, store=STORE) as log:
        write(log, 0, clean)
    if crash_after is not None:
        log = EventLog.open(directory, STREAM, wall_clock=lambda: 7, store=STORE)
        write(log, clean, n)
        log._sync()  # acknowledged, then the process dies: no close, no new high-water mark
        log._closed = True
        os.close(log._fd)
        os.close(log._lock_fd)


def _lines(data: bytes) -> list[bytes]:
    return data.splitlines(keepends=True)


def _record_start(data: bytes, rng: random.Random, last: int = 0) -> int:
    starts = [0, *[i + 1 for i, b in enumerate(data) if b == 0x0A][:-1]]
    if last:
        starts = starts[-last:]
    return rng.choice(starts)


# -- mutations: each changes ``files`` (the victim) in place and returns a description --------


def truncate(rng: random.Random, files: Files, other: Files) -> str:
    data = files[LOG_FILE]
    cut = rng.randrange(len(data))
    files[LOG_FILE] = data[:cut]
    return f"truncate at {cut}"


def truncate_at_record(rng: random.Random, files: Files, other: Files) -> str:
    data = files[LOG_FILE]
    cut = _record_start(data, rng)
    files[LOG_FILE] = data[:cut]
    return f"truncate at record boundary {cut}"


def flip_bit(rng: random.Random, files: Files, other: Files) -> str:
    data = bytearray(files[LOG_FILE])
    i = rng.randrange(len(data))
    bit = rng.randrange(8)
    data[i] ^= 1 << bit
    files[LOG_FILE] = bytes(data)
    return f"flip bit {bit} of byte {i}"


def flip_last_records(rng: random.Random, files: Files, other: Files) -> str:
    lines = _lines(files[LOG_FILE])
    k = rng.randint(1, min(10, len(lines)))
    for j in range(len(lines) - k, len(lines)):
        line = bytearray(lines[j])
        i = rng.randrange(len(line) - 1)  # not the newline: that is the torn-tail case
        line[i] ^= 1 << rng.randrange(8)
        lines[j] = bytes(line)
    files[LOG_FILE] = b"".join(lines)
    return f"flip a bit in each of the last {k} records"


def crlf(rng: random.Random, files: Files, other: Files) -> str:
    files[LOG_FILE] = files[LOG_FILE].replace(b"\n", b"\r\n")
    return "CR LF line endings"


def delete_line(rng: random.Random, files: Files, other: Files) -> str:
    lines = _lines(files[LOG_FILE])
    j = rng.randrange(len(lines))
    del lines[j]
    files[LOG_FILE] = b"".join(lines)
    return f"delete line {j + 1}"


def duplicate_line(rng: random.Random, files: Files, other: Files) -> str:
    lines = _lines(files[LOG_FILE])
    j = rng.randrange(len(lines))
    lines.insert(j, lines[j])
    files[LOG_FILE] = b"".join(lines)
    return f"duplicate line {j + 1}"


def swap_lines(rng: random.Random, files: Files, other: Files) -> str:
    lines = _lines(files[LOG_FILE])
    i, j = rng.sample(range(len(lines)), 2)
    lines[i], lines[j] = lines[j], lines[i]
    files[LOG_FILE] = b"".join(lines)
    return f"swap lines {i + 1} and {j + 1}"


def insert_foreign_line(rng: random.Random, files: Files, other: Files) -> str:
    lines = _lines(files[LOG_FILE])
    foreign = rng.choice(_lines(other[LOG_FILE]))
    j = rng.randrange(len(lines) + 1)
    lines.insert(j, foreign)
    files[LOG_FILE] = b"".join(lines)
    return f"insert another log's line at {j + 1}"


def _edit_value(rng: random.Random, files: Files, recompute: str) -> str:
    lines = _lines(files[LOG_FILE])
    j = rng.randrange(len(lines))
    body, _, crc = lines[j].rpartition(b"\t")
    digits = [i for i, b in enumerate(body) if 0x30 <= b <= 0x39]
    i = rng.choice(digits)
    edited = bytearray(body)
    edited[i] = 0x30 + (edited[i] - 0x30 + rng.randint(1, 9)) % 10
    body = bytes(edited)
    if recompute == "none":
        lines[j] = body + b"\t" + crc
    elif recompute == "plain":
        lines[j] = body + b"\t%08x\n" % zlib.crc32(body)
    else:  # the whole chain from here on, as a forger who knows the format would
        prev = int(lines[j - 1][-9:-1], 16) if j else _genesis(files)
        for k in range(j, len(lines)):
            b = body if k == j else lines[k].rpartition(b"\t")[0]
            prev = zlib.crc32(b, prev)
            lines[k] = b + b"\t%08x\n" % prev
    files[LOG_FILE] = b"".join(lines)
    return f"edit a digit of line {j + 1}, checksum {recompute}"


def _genesis(files: Files) -> int:
    meta = json.loads(files[META_FILE])
    return zlib.crc32(f"{meta['format']}\n{meta['stream']}\n{meta['run_id']}\n".encode())


def edit_value(rng: random.Random, files: Files, other: Files) -> str:
    return _edit_value(rng, files, "none")


def edit_value_plain_crc(rng: random.Random, files: Files, other: Files) -> str:
    return _edit_value(rng, files, "plain")


def edit_value_rechained(rng: random.Random, files: Files, other: Files) -> str:
    return _edit_value(rng, files, "chain")


def splice(rng: random.Random, files: Files, other: Files) -> str:
    mine, theirs = _lines(files[LOG_FILE]), _lines(other[LOG_FILE])
    k = rng.randrange(1, len(mine))
    j = rng.randrange(len(theirs))
    files[LOG_FILE] = b"".join(mine[:k] + theirs[j:])
    return f"splice: lines 1..{k}, then the other log from line {j + 1}"


def append_other_log(rng: random.Random, files: Files, other: Files) -> str:
    files[LOG_FILE] += other[LOG_FILE]
    return "append the other log"


def swap_logs(rng: random.Random, files: Files, other: Files) -> str:
    files[LOG_FILE] = other[LOG_FILE]
    return "the other log's events.log under this meta.json"


def edit_meta(rng: random.Random, files: Files, other: Files) -> str:
    meta = json.loads(files[META_FILE])
    choice = rng.choice(["stream", "run_id", "format", "garbage", "other", "drop_run_id"])
    if choice == "stream":
        meta["stream"] = "robot2"
    elif choice == "run_id":
        meta["run_id"] = "00000000-0000-4000-8000-00000000beef"
    elif choice == "format":
        meta["format"] = "objsearch.events/1"
    elif choice == "drop_run_id":
        del meta["run_id"]
    elif choice == "other":
        files[META_FILE] = other[META_FILE]
        return "the other log's meta.json"
    if choice == "garbage":
        files[META_FILE] = files[META_FILE][: rng.randrange(len(files[META_FILE]))]
    else:
        files[META_FILE] = json.dumps(meta).encode()
    return f"edit meta.json ({choice})"


def edit_durable(rng: random.Random, files: Files, other: Files) -> str:
    if DURABLE_FILE not in files:
        files[DURABLE_FILE] = b'{"seq": 1, "offset": 3, "checksum": "00000000"}\n'
        return "add a wrong durable.json"
    choice = rng.choice(["delete", "garbage", "seq", "offset"])
    if choice == "delete":
        del files[DURABLE_FILE]
    elif choice == "garbage":
        files[DURABLE_FILE] = b'{"seq": '
    else:
        doc = json.loads(files[DURABLE_FILE])
        doc[choice] += rng.choice([-1, 1, 1000])
        files[DURABLE_FILE] = json.dumps(doc).encode()
    return f"edit durable.json ({choice})"


def torn_fragment(rng: random.Random, files: Files, other: Files) -> str:
    line = rng.choice(_lines(other[LOG_FILE]))
    fragment = line[: rng.randrange(1, len(line) - 1)] if rng.random() < 0.7 else b"\0" * 4096
    files[LOG_FILE] += fragment
    return f"append an unterminated fragment of {len(fragment)} byte(s)"


MUTATIONS: tuple[Mutation, ...] = (
    truncate,
    truncate_at_record,
    flip_bit,
    flip_last_records,
    crlf,
    delete_line,
    duplicate_line,
    swap_lines,
    insert_foreign_line,
    edit_value,
    edit_value_plain_crc,
    edit_value_rechained,
    splice,
    append_other_log,
    swap_logs,
    edit_meta,
    edit_durable,
    torn_fragment,
)


def _read_files(directory: Path) -> Files:
    return {p.name: p.read_bytes() for p in directory.iterdir() if p.is_file()}


def _write_files(directory: Path, files: Files) -> None:
    for name, data in files.items():
        (directory / name).write_bytes(data)


def _base_logs(root: Path, events: int) -> dict[str, tuple[Files, list[Event]]]:
    """The logs every case damages a copy of: one closed, one whose writer crashed after two
    thirds, and another log (of the same stream) to splice from."""
    bases: dict[str, tuple[Files, list[Event]]] = {}
    for name, run, crash in (
        ("closed", "00000000-0000-4000-8000-000000000001", None),
        ("crashed", "00000000-0000-4000-8000-000000000002", 2 * events // 3),
        ("other", "00000000-0000-4000-8000-000000000003", None),
    ):
        _make_log(root / name, run, events, crash_after=crash)
        bases[name] = (_read_files(root / name), list(read_log(root / name, store=STORE)))
    return bases


def run_log_fuzz(cases: int, *, seed: int = 0, events: int = 30, verify: str = "all") -> FuzzReport:
    """Run ``cases`` seeded mutations; see the module docstring for what each must satisfy.
    ``verify="sealed"`` opens each damaged log as an agent restarting from a snapshot does
    (the prefix checked by its seals): it must meet the same promise."""
    rng = random.Random(seed)
    report = FuzzReport()
    with tempfile.TemporaryDirectory(prefix="objsearch-logfuzz-") as tmp:
        root = Path(tmp)
        bases = _base_logs(root, events)
        for case in range(cases):
            victim = "closed" if case % 2 == 0 else "crashed"
            files, original = dict(bases[victim][0]), bases[victim][1]
            mutation = MUTATIONS[rng.randrange(len(MUTATIONS))]
            what = f"case {case} ({victim} log): " + mutation(rng, files, bases["other"][0])
            directory = root / f"case-{case}"
            directory.mkdir()
            _write_files(directory, files)
            outcome = _open_as_writer(directory, files, original, verify)
            if outcome.startswith("changed past the mark"):
                outcome = "forged" if mutation is edit_value_rechained else "silent change"
            report.tried += 1
            report.by_mutation[f"{mutation.__name__}: {outcome.split(':')[0]}"] += 1
            if outcome == "refused":
                report.refused += 1
            elif outcome == "unchanged":
                report.unchanged += 1
            elif outcome == "torn_kept":
                report.torn_kept += 1
            elif outcome == "clean_prefix":
                report.clean_prefix += 1
            elif outcome == "forged":
                report.forged += 1
            else:
                kind = outcome.split(":")[0]
                if kind == "traceback":
                    report.traceback += 1
                else:
                    report.silent_change += 1
                report.failures.append(f"{what}: {outcome}")
            shutil.rmtree(directory)
    return report


def _open_as_writer(
    directory: Path, files: Files, original: list[Event], verify: str = "all"
) -> str:
    """What the next writer does with the damaged log, classified."""
    quiet = logging.getLogger("objsearch.events.log")
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", TornTailWarning)
            log = EventLog.open(directory, STREAM, verify=verify, store=STORE)
            with log:
                log.append("search_failed", {"reason": "next"}, time_ns=log.last_time_ns)
                torn = log.torn_tail
            after = list(read_log(directory, store=STORE))
    except EventStoreError:
        now = _read_files(directory)
        if now != files:
            changed = sorted(set(now) ^ set(files) | {k for k in now if now.get(k) != files.get(k)})
            return f"silent change: refused, but changed {changed}"
        return "refused"
    except Exception:
        return "traceback: " + traceback.format_exc(limit=3).replace("\n", " | ")
    finally:
        quiet.setLevel(level)
    kept = after[:-1]
    log_bytes = files.get(LOG_FILE, b"")
    new_bytes = (directory / LOG_FILE).read_bytes()
    if torn is not None:
        assert torn.quarantine is not None
        fragment = torn.quarantine.read_bytes()
        if log_bytes[torn.offset :] != fragment or not new_bytes.startswith(
            log_bytes[: torn.offset]
        ):
            return "silent change: torn fragment not kept byte for byte"
        if kept != original[: len(kept)] or any(
            e.seq in _acknowledged_before_mark(files) for e in original[len(kept) :]
        ):
            return "silent change: events before the high-water mark were cut as a torn tail"
        return "torn_kept" if kept != original else "unchanged"
    if not new_bytes.startswith(log_bytes):
        return "silent change: bytes of events.log removed"
    quarantined = [p for p in directory.iterdir() if p.name.startswith(QUARANTINE_PREFIX)]
    if quarantined:
        return f"silent change: unexpected quarantine files {quarantined}"
    if kept == original:
        return "unchanged"
    mark = max(_acknowledged_before_mark(files), default=0)
    if len(kept) >= mark and kept[:mark] == original[:mark]:
        return "clean_prefix" if kept == original[: len(kept)] else "changed past the mark"
    return f"silent change: opened with {len(kept)} events, not the {len(original)} written"


def _acknowledged_before_mark(files: Files) -> set[int]:
    try:
        mark = json.loads(files[DURABLE_FILE])["seq"]
    except (KeyError, ValueError, TypeError):
        return set()
    return set(range(1, int(mark) + 1)) if isinstance(mark, int) else set()


# -- repair: the same damage, then `objsearch log repair` ------------------------------------


@dataclass
class RepairReport:
    """How ``repair_log`` met each damaged log. ``loss``: a record the damaged file still held
    that is neither in the repaired log nor in a quarantine file; ``silent_change``: a repaired
    log that does not verify, holds an event that is not the one written at its seq, or hands a
    removed record's seq or id to the next append."""

    tried: int = 0
    clear_error: int = 0  # refused with an error naming the problem, nothing changed
    unchanged: int = 0  # nothing to repair (the damage was harmless or past what a writer reads)
    repaired: int = 0
    forged: int = 0  # a re-chained edit: undetectable by design, kept as written
    traceback: int = 0
    silent_change: int = 0
    loss: int = 0
    #: per repair: records the damaged file held intact that the repair moved out anyway
    intact_moved_out: list[int] = field(default_factory=list)
    #: per mutation: repairs that moved ≥ 1 intact record out
    moved_by_mutation: Counter[str] = field(default_factory=Counter)
    by_mutation: Counter[str] = field(default_factory=Counter)
    failures: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.traceback == 0 and self.silent_change == 0 and self.loss == 0

    def summary(self) -> str:
        moved = self.intact_moved_out
        return (
            f"tried {self.tried}: clear error {self.clear_error}, unchanged {self.unchanged}, "
            f"repaired {self.repaired} (forged, kept as written: {self.forged}), traceback "
            f"{self.traceback}, silent change {self.silent_change}, loss {self.loss}; repairs "
            f"that moved intact records out: {sum(1 for m in moved if m)} "
            f"(≥ 100: {sum(1 for m in moved if m >= 100)}; {sum(moved)} records in all)"
        )


def run_repair_fuzz(cases: int, *, seed: int = 0, events: int = 300) -> RepairReport:
    """``cases`` seeded mutations of a closed and a crashed log, each repaired; see
    :class:`RepairReport` for what counts as a failure."""
    from objsearch.events.repair import repair_log, verify_log

    rng = random.Random(seed)
    report = RepairReport()
    with tempfile.TemporaryDirectory(prefix="objsearch-repairfuzz-") as tmp:
        root = Path(tmp)
        bases = _base_logs(root, events)
        quiet = logging.getLogger("objsearch.events.log")
        level = quiet.level
        quiet.setLevel(logging.ERROR)
        try:
            for case in range(cases):
                victim = "closed" if case % 2 == 0 else "crashed"
                files, original = dict(bases[victim][0]), bases[victim][1]
                mutation = MUTATIONS[rng.randrange(len(MUTATIONS))]
                what = f"case {case} ({victim} log): " + mutation(rng, files, bases["other"][0])
                directory = root / f"case-{case}"
                directory.mkdir()
                _write_files(directory, files)
                outcome, moved = _repair_case(
                    directory, files, bases[victim][0][LOG_FILE], original, repair_log, verify_log
                )
                if outcome.startswith("silent change: seq") and mutation is edit_value_rechained:
                    outcome = "forged"  # re-chained past the high-water mark: undetectable
                report.tried += 1
                report.by_mutation[f"{mutation.__name__}: {outcome}"] += 1
                if moved is not None:
                    report.intact_moved_out.append(moved)
                    if moved:
                        report.moved_by_mutation[mutation.__name__] += 1
                if outcome in ("clear error", "unchanged", "repaired", "forged"):
                    attr = outcome.replace(" ", "_")
                    setattr(report, attr, getattr(report, attr) + 1)
                else:
                    kind = outcome.partition(": ")[0]
                    attr = kind.replace(" ", "_")
                    setattr(report, attr, getattr(report, attr) + 1)
                    report.failures.append(f"{what}: {outcome}")
                shutil.rmtree(directory)
        finally:
            quiet.setLevel(level)
    return report


def _repair_case(
    directory: Path,
    files: Files,
    written_log: bytes,
    original: list[Event],
    repair_log: Callable[..., Any],
    verify_log: Callable[..., Any],
) -> tuple[str, int | None]:
    """(outcome, intact records moved out) of repairing one damaged log; ``written_log`` is
    the undamaged events.log whose records are ``original``."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", TornTailWarning)
            result = repair_log(directory, store=STORE)
            verify_log(directory, store=STORE)
            after = list(read_log(directory, upcast=False, store=STORE))
            with EventLog.open(directory, STREAM, store=STORE) as log:
                appended = log.append("search_failed", {"reason": "next"}, time_ns=log.last_time_ns)
    except EventStoreError as exc:
        if _read_files(directory) != files:
            return f"silent change: refused ({exc}), but changed files", None
        return "clear error", None
    except Exception:
        return "traceback: " + traceback.format_exc(limit=4).replace("\n", " | "), None
    written = {e.seq: e for e in original}
    for event in after:
        if event.type != "record_quarantined" and written.get(event.seq) != event:
            return f"silent change: seq {event.seq} is not the event written there", None
    damaged_lines = set(_lines(files.get(LOG_FILE, b"")))
    record_lines = list(zip(_lines(written_log), original, strict=True))
    kept_lines = set(_lines((directory / LOG_FILE).read_bytes()))
    quarantined = b"".join(
        p.read_bytes() for p in directory.iterdir() if p.name.startswith(QUARANTINE_PREFIX)
    )
    still_there = [(line, e) for line, e in record_lines if line in damaged_lines]
    lost = [e.seq for line, e in still_there if line not in kept_lines and line not in quarantined]
    if lost:
        return f"loss: seqs {lost[:5]} neither kept nor quarantined", None
    mark = _acknowledged_before_mark(files)
    known = {e.event_id for _, e in still_there} | {e.event_id for e in original if e.seq in mark}
    if appended.event_id in known - {e.event_id for e in after}:
        return f"silent change: the next append (seq {appended.seq}) reused a removed id", None
    moved = sum(1 for line, _ in still_there if line not in kept_lines)
    return ("repaired" if result.changed else "unchanged"), moved


# -- snapshots: a restore trusts only what the log's writer attested -------------------------


class _CountsProjection:
    """A small snapshottable projection: events per type (what the fuzzer restores)."""

    snapshot_name: ClassVar[str] = "counts"
    snapshot_version: ClassVar[int] = 1

    def __init__(self, counts: dict[str, int] | None = None, last_seq: int = 0) -> None:
        self.counts = dict(counts or {})
        self.last_seq = last_seq

    @property
    def state(self) -> dict[str, int]:
        return self.counts

    def apply(self, event: Event) -> None:
        self.counts[event.type] = self.counts.get(event.type, 0) + 1
        self.last_seq = event.seq

    def to_snapshot(self) -> dict[str, Any]:
        return {"counts": self.counts}

    @classmethod
    def from_snapshot(cls, state: dict[str, Any], last_seq: int) -> _CountsProjection:
        counts = state["counts"]
        if not (isinstance(counts, dict) and all(type(v) is int for v in counts.values())):
            raise ValueError("counts: not a mapping of type to count")
        return cls(counts, last_seq)


@dataclass
class SnapshotReport:
    tried: int = 0
    rebuilt: int = 0  # not trusted: logged once, rebuilt from the log (the clear error)
    unchanged: int = 0  # the damage left the snapshot byte for byte valid (or it was trusted)
    traceback: int = 0
    silent_change: int = 0  # restored state differs from the log's fold
    failures: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.traceback == 0 and self.silent_change == 0

    def summary(self) -> str:
        return (
            f"tried {self.tried}: rebuilt with one log line {self.rebuilt}, trusted unchanged "
            f"{self.unchanged}, traceback {self.traceback}, silent change {self.silent_change}, "
            "loss 0 (a restore never writes the log)"
        )


def run_snapshot_fuzz(cases: int, *, seed: int = 0, events: int = 60) -> SnapshotReport:
    """Damage an attested snapshot every way (flipped bits, edited state with its CRC
    recomputed, another log's snapshot, a stale one, malformed state, truncation) and restore:
    the result must equal the log's fold every time."""
    from objsearch.events.projection import fold
    from objsearch.events.snapshot import restore, save_snapshot, snapshot_path

    rng = random.Random(seed)
    report = SnapshotReport()
    with tempfile.TemporaryDirectory(prefix="objsearch-snapfuzz-") as tmp:
        root = Path(tmp)
        logs = {}
        for name, run in (("mine", "01"), ("other", "02")):
            _make_log(root / name, f"00000000-0000-4000-8000-0000000000{run}", events)
            save_snapshot(
                root / f"{name}-snaps",
                fold(read_log(root / name, store=STORE), _CountsProjection()),
                log=root / name,
                store=STORE,
            )
            logs[name] = snapshot_path(root / f"{name}-snaps", "counts").read_bytes()
        truth = fold(read_log(root / "mine", store=STORE), _CountsProjection()).counts
        path = snapshot_path(root / "mine-snaps", "counts")
        quiet = logging.getLogger("objsearch.events.snapshot")
        for case in range(cases):
            data = bytearray(logs["mine"])
            kind = rng.choice(["flip", "edit", "other", "truncate", "malformed", "none"])
            if kind == "flip":
                data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
            elif kind in ("edit", "malformed"):
                doc = json.loads(bytes(data))
                del doc["crc32"]
                if kind == "edit":
                    key = rng.choice(sorted(doc["state"]["counts"]))
                    doc["state"]["counts"][key] += rng.randint(1, 5)
                else:
                    doc["state"] = rng.choice([{}, {"counts": [1]}, None, {"counts": {"x": "1"}}])
                text = json.dumps(doc, sort_keys=True, separators=(",", ":"))
                data = bytearray(
                    (text[:-1] + f',"crc32":"{zlib.crc32(text.encode()):08x}"}}\n').encode()
                )
            elif kind == "other":
                data = bytearray(logs["other"])
            elif kind == "truncate":
                data = data[: rng.randrange(len(data))]
            path.write_bytes(bytes(data))
            report.tried += 1
            records: list[logging.LogRecord] = []
            handler = _Collect(records)
            quiet.addHandler(handler)
            try:
                restored, how = restore(
                    root / "mine",
                    _CountsProjection,
                    _CountsProjection.from_snapshot,
                    snapshot_dir=path.parent,
                    save=False,
                    store=STORE,
                )
            except Exception:
                report.traceback += 1
                report.failures.append(f"case {case} ({kind}): " + traceback.format_exc(limit=3))
                continue
            finally:
                quiet.removeHandler(handler)
            if restored.counts != truth:
                report.silent_change += 1
                report.failures.append(f"case {case} ({kind}): restored {restored.counts}")
            elif how.rejected is not None:
                if len(records) != 1:
                    report.failures.append(f"case {case} ({kind}): {len(records)} log lines")
                    report.silent_change += 1
                else:
                    report.rebuilt += 1
            else:
                report.unchanged += 1
    return report


class _Collect(logging.Handler):
    def __init__(self, records: list[logging.LogRecord]) -> None:
        super().__init__(logging.INFO)
        self.records = records

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)
