"""A fold of ``read_log`` from records (events/fold_read.py): no event per record, and the same
outcome as folding the events one by one — the same state, or the same error at the same place —
for good logs, old record versions, damaged records, torn tails and cut-offs."""

from __future__ import annotations

import copy
import json
import random
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.scene_graph import SceneGraphProjection, UpdateMode
from objsearch.agent.session import Session, load_context
from objsearch.agent.state import AgentState
from objsearch.agent.strategies import RunSpec
from objsearch.events import Event, EventLog, fold, read_log
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
