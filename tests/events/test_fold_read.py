"""A fold of ``read_log`` from records (events/fold_read.py): no event per record, and the same
outcome as folding the events one by one — the same state, or the same error at the same place —
for good logs, old record versions, damaged records, torn tails and cut-offs."""

from __future__ import annotations

import copy
import json
import random
import re
import warnings
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from objsearch.agent.catalogue import STORE
from objsearch.agent.scene_graph import SceneGraphProjection, UpdateMode
from objsearch.agent.session import Session, load_context
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import RunSpec
from objsearch.events import Event, EventLog, fold, read_log
from objsearch.events.envelope import canonical_ids
from objsearch.events.fold_read import _checksums
from objsearch.sim.models import SIM_MODELS
from objsearch.sim.placements import Schedule
from objsearch.sim.world import SimClock, SimWorld

from .rechain import rechain

GOLDEN = Path(__file__).resolve().parents[1] / "replay" / "golden"
DYNAMIC = ("Apple", "Cup", "Bowl", "Phone")
STATIC = ("Sink", "Table", "Fridge", "Sofa", "Bed")
POSE = {"x": 1.0, "y": 2.0, "yaw": 0.0}


def _detection(rng: random.Random) -> dict[str, Any]:
    static = rng.choice(STATIC)
    return {
        "object_class": rng.choice(DYNAMIC), "instance_id": "i", "mask_area": 900.0,
        "position": [1.0, 2.0, 0.5], "accepted": rng.random() < 0.8,
        "support": {"static_id": f"{static}|1", "static_class": static,
                    "at": rng.random() < 0.5},
        "score": 1.0, "classes": [],
    }  # fmt: skip


def _write(directory: Path, tasks: int = 90, seed: int = 0) -> None:
    """A log of the agent's mix: a run, its prior, then tasks of detections and moves (about
    1,500 records, several of the fold's blocks)."""
    rng = random.Random(seed)
    values = [{"dynamic": d, "static": s, "rel": rng.random()} for d in DYNAMIC for s in STATIC]
    with EventLog.open(directory, "fold", store=STORE) as log, log.batch():
        t = 0

        def add(kind: str, payload: dict[str, Any], task: str | None = None) -> None:
            nonlocal t
            t += 1
            log.append(kind, payload, time_ns=t, task_id=task)

        add("run_started", RunSpec.of("paper", "x", "wpl", seed=seed).payload())
        add("scene_graph_seeded", {"source": "synthetic", "values": values})
        for number in range(1, tasks + 1):
            task = f"task-{number:05d}"
            target = rng.choice(DYNAMIC)
            add("task_started", {"target": target, "start": "kitchen", "pose": POSE,
                                 "scene": 1, "clock": None}, task)  # fmt: skip
            for _ in range(rng.randint(4, 24)):
                if rng.random() < 0.3:
                    add("moved", {"start": POSE, "end": POSE, "metres": rng.random() * 5,
                                  "rooms": ["kitchen"], "interrupted": False}, task)  # fmt: skip
                else:
                    add("detection", _detection(rng), task)
            if number % 7 == 0:
                add("task_aborted", {"target": target, "path_length": 3.0, "reason": "crash"}, task)
            else:
                add("task_ended", {"target": target, "success": True, "path_length": 10.0}, task)


def _rewrite(directory: Path, edits: dict[int, Callable[[dict[str, Any]], None]]) -> None:
    """Change the JSON of the records at ``edits``' line numbers, the chain intact
    (:func:`rechain`), with no seals: the records alone decide."""
    rechain(directory, edits)
    (directory / "durable.json").unlink()


class _Counting(SceneGraphProjection):
    """The scene graph, counting the events handed to ``apply``."""

    applied = 0

    def apply(self, event: Any) -> None:
        self.applied += 1
        super().apply(event)


def _one_by_one(directory: Path) -> Iterator[Event]:
    """``read_log``'s events, handed to a fold one by one (a plain generator, not the log)."""
    yield from read_log(directory, store=STORE)


Outcome = tuple[str, Any, int]


def _outcome(
    make: Callable[[], Any],
    events: Callable[[], Any],
    until_seq: int | None = None,
) -> Outcome:
    """What a fold ends with: its error (type and words) or its snapshot, and its place; and
    the torn-tail warnings it gave."""
    projection = make()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            fold(events(), projection, until_seq=until_seq)
        except Exception as exc:  # any error: the outcome compared
            result: Any = (type(exc).__name__, str(exc))
        else:
            result = projection.to_snapshot()
    said = [str(w.message) for w in caught]
    return json.dumps([result, said], sort_keys=True, default=str), None, projection.last_seq


def _agent() -> AgentState:
    return AgentState(models=SIM_MODELS)


def _both(directory: Path, until_seq: int | None = None) -> None:
    """Folding ``read_log`` (from records) and its events one by one end alike, for the agent's
    state and the scene graph."""
    for make in (_agent, SceneGraphProjection):
        fast = _outcome(make, lambda: read_log(directory, store=STORE), until_seq)
        slow = _outcome(make, lambda: _one_by_one(directory), until_seq)
        assert fast == slow


def test_a_fold_of_read_log_builds_no_event_per_record(tmp_path: Path) -> None:
    _write(tmp_path)
    records = len((tmp_path / "events.log").read_bytes().splitlines())
    fast = fold(read_log(tmp_path, store=STORE), _Counting())
    slow = fold(_one_by_one(tmp_path), _Counting())
    assert slow.applied == records
    # Only the block that holds what the fold must see as an event is read event by event.
    assert fast.applied < records // 4
    assert fast.to_snapshot() == slow.to_snapshot()
    assert fast.last_seq == slow.last_seq == records
    agent = fold(read_log(tmp_path, store=STORE), _agent())
    assert agent.to_snapshot() == fold(_one_by_one(tmp_path), _agent()).to_snapshot()
    assert agent.tasks.open is None and agent.last_time_ns == records


def test_a_task_left_open_keeps_its_metres(tmp_path: Path) -> None:
    _write(tmp_path)
    lines = (tmp_path / "events.log").read_bytes().splitlines(keepends=True)
    ends = [i for i, line in enumerate(lines) if b'"type":"task_ended"' in line]
    (tmp_path / "events.log").write_bytes(b"".join(lines[: ends[-1]]))
    (tmp_path / "durable.json").unlink()
    agent = fold(read_log(tmp_path, store=STORE), _agent())
    assert agent.tasks.open is not None and agent.tasks.open.metres > 0
    _both(tmp_path)


@pytest.mark.parametrize("golden", sorted(p.parent.name for p in GOLDEN.glob("*/events.log")))
def test_the_golden_logs_fold_alike(golden: str) -> None:
    _both(GOLDEN / golden)


@pytest.mark.parametrize("until_seq", [1, 2, 3, 170, 171, 500, 1_000_000])
def test_a_cut_off_folds_alike(tmp_path: Path, until_seq: int) -> None:
    _write(tmp_path)
    _both(tmp_path, until_seq)


def _set(key: str, value: Any) -> Callable[[dict[str, Any]], None]:
    def edit(record: dict[str, Any]) -> None:
        record[key] = value

    return edit


def _payload(key: str, value: Any) -> Callable[[dict[str, Any]], None]:
    def edit(record: dict[str, Any]) -> None:
        record["payload"][key] = value

    return edit


def _drop(key: str) -> Callable[[dict[str, Any]], None]:
    def edit(record: dict[str, Any]) -> None:
        del record["payload"][key]

    return edit


def _upper_id(record: dict[str, Any]) -> None:
    record["event_id"] = record["event_id"].upper()


def _as_v2(record: dict[str, Any]) -> None:
    """A detection as version 2 wrote it (no score, no classes): upcast when read."""
    if record["type"] == "detection":
        record["version"] = 2
        del record["payload"]["score"], record["payload"]["classes"]


DAMAGE: dict[str, Callable[[dict[str, Any]], None]] = {
    "id not canonical": _upper_id,
    "seq gap": _set("seq", 10**6),
    "another stream": _set("stream", "other"),
    "unknown type": _set("type", "no_such_type"),
    "unknown version": _set("version", 99),
    "time backwards": _set("time_ns", 0),
    "payload not an object": _set("payload", [1, 2]),
    "unknown envelope field": _set("extra", 1),
    "payload misses a field": _drop("accepted"),
    "payload of the wrong type": _payload("accepted", "yes"),
    "payload has an unknown field": _payload("extra", 1),
    "old version": _as_v2,
}


@pytest.mark.parametrize("damage", sorted(DAMAGE))
@pytest.mark.parametrize("line", [5, 300, 301])
def test_a_damaged_or_old_record_folds_alike(tmp_path: Path, damage: str, line: int) -> None:
    _write(tmp_path)
    lines = (tmp_path / "events.log").read_bytes().splitlines()
    # The damage on a detection (its payload is the one both folds read).
    at = next(n for n in range(line, len(lines)) if b'"type":"detection"' in lines[n - 1])
    _rewrite(tmp_path, {at: DAMAGE[damage]})
    _both(tmp_path)


def test_every_detection_of_an_old_version_folds_alike(tmp_path: Path) -> None:
    _write(tmp_path)
    count = len((tmp_path / "events.log").read_bytes().splitlines())
    _rewrite(tmp_path, {n: _as_v2 for n in range(1, count + 1)})
    _both(tmp_path)


@pytest.mark.parametrize("where", ["crc", "torn", "cut", "crlf"])
def test_damaged_framing_folds_alike(tmp_path: Path, where: str) -> None:
    _write(tmp_path)
    path = tmp_path / "events.log"
    data = path.read_bytes()
    if where == "crc":  # one checksum digit changed, mid-log
        at = data.index(b"\t", len(data) // 2)
        data = data[: at + 1] + (b"0" if data[at + 1 : at + 2] != b"0" else b"1") + data[at + 2 :]
    elif where == "torn":  # an append cut short: bytes after the last newline
        data = data + data[: len(data) // 3].splitlines()[-1][:40]
    elif where == "cut":  # the log ends before its durable high-water mark
        data = data[: data.rindex(b"\n", 0, len(data) - 1) + 1]
    else:
        data = data.replace(b"\n", b"\r\n", 1)
    path.write_bytes(data)
    _both(tmp_path)


@pytest.mark.parametrize("where", ["upper case", "blank", "no tab", "short line", "inner tab"])
def test_a_checksum_written_otherwise_folds_alike(tmp_path: Path, where: str) -> None:
    """A checksum the scan would not read as the chain's (upper case, a blank for a digit, no
    tab before it, a line too short to hold one), mid-log: the same error at the same place;
    and a tab inside a record's JSON (blank space to JSON), which both read."""
    _write(tmp_path)
    path = tmp_path / "events.log"
    lines = path.read_bytes().splitlines()
    n = len(lines) // 2
    line = lines[n]
    if where == "upper case":
        line = line[:-9] + line[-9:].upper()
        assert line != lines[n]  # a digit of this log's checksum there is a letter
    elif where == "blank":
        line = line[:-4] + b" " + line[-3:]
    elif where == "no tab":
        line = line[:-9] + b" " + line[-8:]
    elif where == "short line":
        line = b"\t0"
    else:  # blank space JSON allows, chained as a writer would chain it
        line = line[:-9].replace(b'"seq":', b'"seq":\t', 1) + b"\t00000000"
    lines[n] = line
    if where == "inner tab":
        lines = _chain_of(tmp_path, lines)
        (tmp_path / "durable.json").unlink()
    path.write_bytes(b"".join(line + b"\n" for line in lines))
    if where == "inner tab":
        assert fold(read_log(tmp_path, store=STORE), _agent()).last_seq == len(lines)
    _both(tmp_path)


def _chain_of(directory: Path, lines: list[bytes]) -> list[bytes]:
    """``lines`` with every checksum chained again (each line's body: up to its last tab)."""
    from objsearch.events.log_files import read_meta

    chain = read_meta(directory).genesis
    out = []
    for line in lines:
        body = line.rpartition(b"\t")[0]
        chain = zlib.crc32(body, chain)
        out.append(body + b"\t%08x" % chain)
    return out


def _checked_line_by_line(lines: list[bytes], chain: int | None) -> list[int] | None:
    """What the scan checks, one line at a time: each line a body, a tab and the 8 lower-case
    hex digits of its checksum (chained from ``chain``, or of the body alone if None)."""
    values = []
    for line in lines:
        value = zlib.crc32(line[:-9], 0 if chain is None else chain)
        if chain is not None:
            chain = value
        if line[-9:] != b"\t%08x" % value:
            return None
        values.append(value)
    return values


_TAIL_BYTES = b"0123456789abcdefABCDEF \t\x0b\xe9x-+"


@st.composite
def _framed_lines(draw: st.DrawFn) -> tuple[list[bytes], int | None]:
    """Lines chained as a log writes them, then perhaps a byte or two of their last nine
    changed, a line cut short, or a checksum written in upper case."""
    chain = draw(st.one_of(st.none(), st.integers(0, 2**32 - 1)))
    bodies = draw(st.lists(st.binary(max_size=40).filter(lambda b: b"\n" not in b), min_size=1,
                           max_size=6))  # fmt: skip
    lines, running = [], chain
    for body in bodies:
        value = zlib.crc32(body, 0 if running is None else running)
        if running is not None:
            running = value
        lines.append(body + b"\t%08x" % value)
    for _ in range(draw(st.integers(0, 2))):
        k = draw(st.integers(0, len(lines) - 1))
        line = bytearray(lines[k])
        if not line:
            continue  # cut to nothing already
        how = draw(st.sampled_from(["byte", "cut", "upper"]))
        if how == "byte":
            at = len(line) - 1 - draw(st.integers(0, min(8, len(line) - 1)))
            line[at] = draw(st.sampled_from(_TAIL_BYTES))
        elif how == "cut":
            del line[draw(st.integers(0, len(line) - 1)) :]
        else:  # the same number, in upper case
            line[-8:] = line[-8:].upper()
        lines[k] = bytes(line)
    return lines, chain


@given(_framed_lines())
def test_the_block_checksum_check_is_the_scans(framed: tuple[list[bytes], int | None]) -> None:
    lines, chain = framed
    bodies = [line[:-9] for line in lines]
    assert _checksums(lines, bodies, chain, zlib.crc32) == _checked_line_by_line(lines, chain)


_ID_ALPHABET = "0123456789abcdefABCDEF-g{}_ 0\u0660\uff10\u00e9\n\t"


@st.composite
def _ids_of_36(draw: st.DrawFn) -> list[str]:
    """Canonical ids, some with a character or two changed (each 36 characters, as the
    decoder hands them on)."""
    ids = []
    for _ in range(draw(st.integers(1, 5))):
        chars = list(str(draw(st.uuids())))
        for _ in range(draw(st.integers(0, 2))):
            chars[draw(st.integers(0, 35))] = draw(st.sampled_from(_ID_ALPHABET))
        ids.append("".join(chars))
    return ids


#: A canonical UUID's spelling, the rule the block check must keep (its regex before 5e000c6).
_UUID_SPELLING = re.compile(
    r"[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}", re.ASCII
)


@given(_ids_of_36())
def test_the_block_id_check_is_the_uuid_spelling(ids: list[str]) -> None:
    assert canonical_ids(ids) == all(_UUID_SPELLING.fullmatch(i) for i in ids)


def test_the_durable_mark_on_another_record_folds_alike(tmp_path: Path) -> None:
    _write(tmp_path)
    durable = json.loads((tmp_path / "durable.json").read_text())
    durable["offset"] -= 1
    (tmp_path / "durable.json").write_text(json.dumps(durable))
    _both(tmp_path)


def test_a_copy_folds_into_itself_not_into_its_original(tmp_path: Path) -> None:
    """The scene graph keeps its handlers (made once): a deep copy makes its own. (The agent's
    state cannot be deep-copied: its models are a read-only mapping.)"""
    _write(tmp_path)
    original = fold(read_log(tmp_path, store=STORE), SceneGraphProjection(), until_seq=400)
    before = json.dumps(original.to_snapshot(), sort_keys=True)
    copied = fold(read_log(tmp_path, store=STORE), copy.deepcopy(original))
    assert json.dumps(original.to_snapshot(), sort_keys=True) == before
    assert original.last_seq == 400
    whole = fold(_one_by_one(tmp_path), SceneGraphProjection())
    assert copied.to_snapshot() == whole.to_snapshot() and copied.last_seq == whole.last_seq


def test_a_fresh_simulated_run_folds_alike(tmp_path: Path) -> None:
    """A log the agent writes today: searches of the paper's home, recorded by a real session
    (its perfect detector writes detections v2, so its blocks are the scan's)."""
    ctx = load_context("paper")
    schedule = Schedule.load(ctx.home, "table2")
    starts = list(ctx.home.starts.items())
    spec = RunSpec.for_home(ctx.home, "wpl", seed=1, update_mode=UpdateMode.ALL)
    session = Session.start(ctx, tmp_path, spec, stream="fresh", wall_clock=lambda: 1)
    try:
        clock = SimClock(session.resume_time_ns)
        for target, (start_name, pose) in zip(("Phone", "Cup", "Vase"), starts, strict=False):
            clock.advance(60.0)
            world = SimWorld(ctx.home, ctx.navmap, schedule.scenes[3], pose, clock=clock)
            session.search(world, target, start_name, scene=3)
    finally:
        session.close()
    records = len((tmp_path / "events.log").read_bytes().splitlines())
    _both(tmp_path)
    for until_seq in (records // 3, records // 2):
        _both(tmp_path, until_seq)


def test_a_log_upgraded_half_way_is_read_from_records_again(tmp_path: Path) -> None:
    """Detections v2 in the first fifth (blocks the scan reads), v3 after: the fold goes back to
    the records once the old blocks are behind it, and ends as the events' fold."""
    _write(tmp_path, tasks=180)
    records = len((tmp_path / "events.log").read_bytes().splitlines())
    _rewrite(tmp_path, {n: _as_v2 for n in range(1, records // 5)})
    counted = fold(read_log(tmp_path, store=STORE), _Counting())
    assert records // 5 <= counted.applied < records // 2
    _both(tmp_path)


class _FailingAt(SceneGraphProjection):
    """The scene graph, failing on the detection at ``fail_at`` (as an event or a record)."""

    fail_at = 0
    made: dict[str, Any] | None = None

    def apply(self, event: Any) -> None:
        if event.seq == self.fail_at:
            raise RuntimeError(f"failed at {event.seq}")
        super().apply(event)

    def record_handlers(self, sightings: Any = None) -> dict[str, Any]:
        if self.made is None:
            handlers = dict(super().record_handlers())
            detection = handlers["detection"]

            def failing(r: Any) -> None:
                if r.seq == self.fail_at:
                    raise RuntimeError(f"failed at {r.seq}")
                detection(r)

            handlers["detection"] = failing
            self.made = handlers
        return self.made


@pytest.mark.parametrize("line", [3, 300, 301])
def test_a_fold_that_fails_mid_block_stops_where_the_events_fold_stops(
    tmp_path: Path, line: int
) -> None:
    """A handler that raises: the fold stands on the record before it, as the events' fold
    does (and as the loop over a block with events in it does)."""
    _write(tmp_path)
    lines = (tmp_path / "events.log").read_bytes().splitlines()
    at = next(n for n in range(line, len(lines)) if b'"type":"detection"' in lines[n - 1])
    ends = []
    readers: list[Callable[[], Iterator[Event]]] = [
        lambda: read_log(tmp_path, store=STORE),
        lambda: _one_by_one(tmp_path),
    ]
    for events in readers:
        projection = _FailingAt()
        projection.fail_at = at
        with pytest.raises(RuntimeError, match=f"failed at {at}"):
            fold(events(), projection)
        ends.append((projection.last_seq, projection.to_snapshot()))
    assert ends[0] == ends[1]
    assert ends[0][0] == at - 1
