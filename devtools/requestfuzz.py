"""A seeded fuzzer for what the agent and the stand-in robot read from the network.

Each case starts from a valid message of one request type — a find or a where request (agent), an open or a
reset request (stand-in robot), a goal pose (stand-in robot) — and breaks it: one field gets a
value of the wrong type, NaN, ±Infinity, a number too big for any integer or float, a string too
long or with characters a name cannot have, or the field is dropped or an unknown one added; or
the whole message is replaced by JSON that is not an object, broken or deeply nested JSON, a
document over the size limit, a String whose bytes are not UTF-8, a CDR length that lies, or
random bytes. Every case is built to be invalid, and the fuzzer knows what must happen to it:

* ``error``: it has a usable id, so the server must answer ``{id, ok: false, error}`` with an
  error naming the broken field;
* ``drop``: it cannot be answered (no usable id, not JSON, not CDR, a goal with a non-finite
  pose), so the receiver must drop it with a ``dropped a message`` log line.

:class:`Fuzzer` sends the cases over a real transport and tallies what came back;
``tests/runtime/test_request_fuzz.py`` and ``benchmarks/request_fuzz.py`` run it against real
``objsearch agent run`` / ``objsearch robot sim`` processes.
"""

from __future__ import annotations

import json
import random
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from objsearch.agent.geometry import Pose
from objsearch.ros.qos import QoS
from objsearch.runtime import messages as m
from objsearch.runtime.config import RuntimeConfig
from objsearch.runtime.node import Node
from objsearch.runtime.requests import MAX_DOCUMENT_BYTES
from objsearch.runtime.transport import TransportConfig

#: Values no field of any request accepts, as raw JSON text (so NaN and 1e400 can be written).
ANY_BAD = [
    "true",
    "false",
    "{}",
    '{"a": 1}',
    "[]",
    "[1]",
    '["Apple"]',
    "NaN",
    "Infinity",
    "-Infinity",
    "1e400",
    "-1e400",
    "1.5",
    "-0.0",
    str(2**64),
    str(-(2**63) - 1),
    "1" * 5000,  # more digits than Python's int() takes
    '"\\u0000"',
    '"\\ud800"',  # a lone surrogate
    '"Apple\\n"',
    '" Apple"',
    '"' + "x" * 200 + '"',
    '"../../etc/passwd"',
    '"Äpfel"',
    '"a\\"b"',
    '"<script>"',
    '""',
]
#: Wrong for a name (target, start, static_id), though some are valid JSON strings or numbers.
BAD_NAMES = [*ANY_BAD, "0", "-1", "7"]
#: Names that are well formed but name nothing the receiver knows (answered with an error).
UNKNOWN_NAMES = ['"Unicorn"', '"Fridge"', '"Sink"', '"kitchen/Nothing|0|0"', '"x|y"']
BAD_INTS = [*ANY_BAD, "-1", str(2**63), '"1"', '"soon"', '"abc"', "1.0"]
BAD_IDS = ["null", "0", "5", '""', '" "', '"a b"', '"' + "i" * 200 + '"', "[]", '{"id": "x"}']


@dataclass(frozen=True, slots=True)
class RequestCase:
    kind: str  # find | where | open | reset | goal
    topic: str
    msgtype: str
    payload: bytes
    expect: str  # error | drop
    rid: str | None
    note: str
    field: str | None = None  # the field the error must name


#: Which process reads each kind of case (and so must log the drop).
RECEIVER = {"find": "agent", "where": "agent", "open": "robot", "reset": "robot", "goal": "robot"}


@dataclass
class FuzzCounts:
    tried: int = 0
    error_answered: int = 0
    dropped: int = 0  # sent as cases that must be dropped (checked against the log lines)
    served: int = 0  # valid requests answered correctly
    crashed: int = 0
    wrong: list[str] = field(default_factory=list)  # cases whose answer was not as expected
    drops_by: dict[str, int] = field(default_factory=lambda: {"agent": 0, "robot": 0})

    def line(self) -> str:
        return (
            f"tried {self.tried}  error-answered {self.error_answered}  dropped {self.dropped}  "
            f"served {self.served}  crashed {self.crashed}  wrong {len(self.wrong)}"
        )


def _string_cdr(data: bytes) -> bytes:
    """A std_msgs/String's CDR around ``data`` taken as is (it need not be UTF-8)."""
    return b"\x00\x01\x00\x00" + struct.pack("<I", len(data) + 1) + data + b"\x00"


def _doc(fields: dict[str, str]) -> str:
    return "{" + ",".join(f"{json.dumps(k)}:{v}" for k, v in fields.items()) + "}"


class CaseMaker:
    """Invalid messages, each from a valid one of a request type; same seed, same cases."""

    def __init__(self, config: RuntimeConfig, seed: int) -> None:
        self.rng = random.Random(seed)
        self.topics = config.topics
        self.n = 0

    def _rid(self) -> str:
        self.n += 1
        return f"fuzz-{self.n:06d}-{self.rng.randrange(16**6):06x}"

    def bases(self, rid: str) -> dict[str, tuple[str, dict[str, str], dict[str, list[str]]]]:
        """kind → (topic, valid fields as JSON text, bad values for each field)."""
        t = self.topics
        return {
            "find": (
                t.find,
                {
                    "id": json.dumps(rid),
                    "target": '"Apple"',
                    "start": '"kitchen-1"',
                    "scene": "1",
                    "not_before_ns": "0",
                },
                {
                    "target": [*BAD_NAMES, *UNKNOWN_NAMES, "null"],
                    "start": BAD_NAMES,
                    "scene": [*BAD_INTS, str(2**31)],
                    "not_before_ns": BAD_INTS,
                },
            ),
            "where": (
                t.where,
                {"id": json.dumps(rid), "target": '"Apple"'},
                {"target": [*BAD_NAMES, *UNKNOWN_NAMES, "null"]},
            ),
            "open": (
                t.open,
                {"id": json.dumps(rid), "static_id": '"kitchen/Fridge|0|0"'},
                {"static_id": [*BAD_NAMES, *UNKNOWN_NAMES, "null"]},
            ),
            "reset": (
                t.sim_reset,
                {"id": json.dumps(rid), "scene": "1", "start": '"kitchen-1"'},
                {
                    "scene": [*BAD_INTS, str(2**31), "999999"],
                    "start": [*BAD_NAMES, '"nowhere"', "null"],
                },
            ),
        }

    def case(self) -> RequestCase:
        r = self.rng.random()
        if r < 0.08:
            return self._goal()
        kind = self.rng.choice(["find", "find", "find", "where", "open", "reset"])
        rid = self._rid()
        topic, valid, bad = self.bases(rid)[kind]
        if r < 0.55:  # one field gets a bad value
            key = self.rng.choice(sorted(bad))
            fields = {**valid, key: self.rng.choice(bad[key])}
            note = f"{key}={fields[key][:40]}"
            return self._json(kind, topic, _doc(fields), "error", rid, note, key)
        if r < 0.62:  # a required field left out
            key = self.rng.choice(["target"] if kind in ("find", "where") else sorted(bad))
            fields = {k: v for k, v in valid.items() if k != key}
            if kind == "reset" and key == "scene":  # scene may be left out: break start instead
                fields["start"] = "7"
                key = "start"
            return self._json(kind, topic, _doc(fields), "error", rid, f"no {key}", key)
        if r < 0.67:  # an unknown field
            name = self.rng.choice(["Target", "extra", "id2", "__proto__", "x" * 100])
            fields = {**valid, name: self.rng.choice(["1", '"a"', "null", "NaN"])}
            return self._json(kind, topic, _doc(fields), "error", rid, f"unknown {name[:20]}", name)
        if r < 0.75:  # the id broken: cannot be answered
            fields = {**valid, "id": self.rng.choice(BAD_IDS)}
            if self.rng.random() < 0.2:
                del fields["id"]
            return self._json(kind, topic, _doc(fields), "drop", None, "bad id")
        return self._whole(kind, topic, valid)

    def _json(
        self,
        kind: str,
        topic: str,
        text: str,
        expect: str,
        rid: str | None,
        note: str,
        key: str | None = None,
    ) -> RequestCase:
        payload = _string_cdr(text.encode("utf-8", "surrogatepass"))
        return RequestCase(kind, topic, m.STRING, payload, expect, rid, note, key)

    def _whole(self, kind: str, topic: str, valid: dict[str, str]) -> RequestCase:
        """The whole message broken: never answerable."""
        rng = self.rng
        choice = rng.randrange(10)
        good = _doc(valid).encode()
        if choice == 0:
            text = rng.choice(["", "{", "null", "[]", "42", '"find"', "NaN", "[1,2", "{}x", "}"])
            return self._json(kind, topic, text, "drop", None, f"not an object: {text!r}")
        if choice == 1:
            cut = rng.randrange(1, len(good))
            return self._json(kind, topic, good[:cut].decode(), "drop", None, "truncated json")
        if choice == 2:
            depth = rng.choice([100, 1000, 5000])
            return self._json(kind, topic, "[" * depth + "]" * depth, "drop", None, "nested")
        if choice == 3:  # over the size limit, though it has an id
            pad = '"' + "p" * (MAX_DOCUMENT_BYTES + rng.randrange(1000)) + '"'
            text = _doc({**valid, "pad": pad})
            return self._json(kind, topic, text, "drop", None, "oversized")
        if choice == 4:  # not UTF-8
            data = good[:-1] + bytes([rng.choice([0x80, 0xC3, 0xFF, 0xED])]) + b"}"
            return RequestCase(kind, topic, m.STRING, _string_cdr(data), "drop", None, "not utf-8")
        if choice == 5:  # a CDR length that lies
            n = rng.choice([0, 2**31, 2**32 - 1, len(good) + 50])
            payload = b"\x00\x01\x00\x00" + struct.pack("<I", n) + good
            return RequestCase(kind, topic, m.STRING, payload, "drop", None, f"cdr length {n}")
        if choice == 6:  # a big-endian or unknown encapsulation header
            header = rng.choice([b"\x00\x00\x00\x00", b"\x00\x07\x00\x00", b"\xff\xff"])
            payload = header + _string_cdr(good)[4:]
            return RequestCase(kind, topic, m.STRING, payload, "drop", None, "bad encapsulation")
        if choice == 7:
            payload = b"" if rng.random() < 0.3 else b"\x00\x01\x00\x00"[: rng.randrange(4)]
            return RequestCase(kind, topic, m.STRING, payload, "drop", None, "empty or short")
        payload = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 200)))
        return RequestCase(kind, topic, m.STRING, payload, "drop", None, "random bytes")

    def _goal(self) -> RequestCase:
        """A goal pose the stand-in must not act on: a non-finite pose, or bytes that are not
        a PoseStamped."""
        rng = self.rng
        topic = self.topics.goal
        if rng.random() < 0.3:
            payload = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 120)))
            return RequestCase("goal", topic, m.POSE_STAMPED, payload, "drop", None, "random bytes")
        msg = m.pose_stamped(Pose(1.0, 1.0, 0.0), 10**9)
        bad = rng.choice([float("nan"), float("inf"), float("-inf")])
        where = rng.choice(["x", "y", "qz", "qw"])
        if where in ("x", "y"):
            setattr(msg.pose.position, where, bad)
        else:
            setattr(msg.pose.orientation, where[1], bad)
        note = f"{where}={bad}"
        return RequestCase(
            "goal", topic, m.POSE_STAMPED, m.encode(msg, m.POSE_STAMPED), "drop", None, note
        )

    def cases(self, n: int) -> Iterator[RequestCase]:
        for _ in range(n):
            yield self.case()


class Fuzzer:
    """Sends cases on a node of its own and checks each answer (or its absence)."""

    def __init__(self, node: Node, config: RuntimeConfig, seed: int) -> None:
        self.node = node
        self.config = config
        self.maker = CaseMaker(config, seed)
        self._pubs: dict[str, Any] = {}
        self._answers: dict[str, dict[str, Any]] = {}
        self._cond = threading.Condition()
        t, q = config.topics, config.qos.requests
        for topic in (t.find_result, t.where_result, t.open_result, t.sim_reset_result):
            node.transport.subscribe(topic, m.STRING, q, self._on_result)
        # Every publisher up front: one created at its first case could lose that case while
        # discovery matches it (an answerable case would then wait for nothing).
        for topic, _, _ in self.maker.bases("-").values():
            self._publisher(topic, m.STRING, q)
        self._publisher(t.goal, m.POSE_STAMPED, config.qos.goal)

    def _on_result(self, data: bytes) -> None:
        doc = json.loads(m.decode(data, m.STRING).data)
        with self._cond:
            self._answers[str(doc.get("id"))] = doc
            self._cond.notify_all()

    def _publisher(self, topic: str, msgtype: str, qos: QoS) -> Any:
        key = f"{topic} {msgtype}"
        if key not in self._pubs:
            self._pubs[key] = self.node.transport.publisher(topic, msgtype, qos)
        return self._pubs[key]

    def _publish(self, case: RequestCase) -> None:
        qos = self.config.qos.goal if case.kind == "goal" else self.config.qos.requests
        self._publisher(case.topic, case.msgtype, qos).publish(case.payload)

    def wait_answer(self, rid: str, timeout_s: float) -> dict[str, Any] | None:
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while rid not in self._answers:
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._cond.wait(left)
            return self._answers.pop(rid)

    def run(
        self, n: int, counts: FuzzCounts, *, timeout_s: float = 10.0, pace_s: float = 0.002
    ) -> None:
        """Send ``n`` cases; ``counts`` gets the tally (``wrong`` names each unexpected outcome).

        An answerable case waits for its answer before the next is sent; a dropped one is
        followed by a short pause, so the middleware never has a reason to drop a message."""
        for case in self.maker.cases(n):
            counts.tried += 1
            self._publish(case)
            if case.expect == "drop":
                counts.dropped += 1
                counts.drops_by[RECEIVER[case.kind]] += 1
                time.sleep(pace_s)
                continue
            assert case.rid is not None
            answer = self.wait_answer(case.rid, timeout_s)
            if answer is None:
                counts.wrong.append(f"{case.kind} {case.note}: no answer in {timeout_s:g} s")
            elif answer.get("ok") is not False or not isinstance(answer.get("error"), str):
                counts.wrong.append(f"{case.kind} {case.note}: answered {answer}")
            elif case.field is not None and f"field {case.field!r}" not in answer["error"]:
                counts.wrong.append(f"{case.kind} {case.note}: error names no field: {answer}")
            else:
                counts.error_answered += 1


# -- against real processes --------------------------------------------------------------------


@dataclass
class Rig:
    """A zenoh router, ``objsearch robot sim`` and ``objsearch agent run`` on 127.0.0.1, each
    logging to a file in ``workdir``."""

    workdir: Path
    port: int
    procs: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)

    @property
    def args(self) -> list[str]:
        return ["--transport", "zenoh", "--connect", f"tcp/127.0.0.1:{self.port}"]

    def config(self) -> RuntimeConfig:
        return RuntimeConfig(transport=TransportConfig(connect=(f"tcp/127.0.0.1:{self.port}",)))

    def start(self, robot_toml: str = "") -> None:
        endpoint = f"tcp/127.0.0.1:{self.port}"
        self._spawn("router", "robot", "router", "--listen", endpoint)
        self._wait_listening("router", self.port)
        self._spawn("robot", "robot", "sim", *self.args)
        config = self.workdir / "robot.toml"
        config.write_text(robot_toml)
        log = str(self.workdir / "log")
        self._spawn("agent", "agent", "run", *self.args, "--config", str(config), "--log", log)

    def _spawn(self, name: str, *args: str) -> None:
        out = (self.workdir / f"{name}.txt").open("wb")
        self.procs[name] = subprocess.Popen(
            [sys.executable, "-m", "objsearch.cli", *args], stdout=out, stderr=subprocess.STDOUT
        )

    def _wait_listening(self, name: str, port: int, timeout_s: float = 120.0) -> None:
        """Until ``name`` accepts connections on 127.0.0.1:``port``: a fresh interpreter takes
        seconds on a loaded machine, so readiness is watched for, never assumed after a pause."""
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1.0).close()
                return
            except OSError:
                if not self.alive(name):
                    raise RuntimeError(f"{name} exited: {self.output(name)[-2000:]}") from None
                if time.monotonic() > deadline:
                    raise TimeoutError(
                        f"{name} is not listening on {port} after {timeout_s:g} s"
                    ) from None
                time.sleep(0.05)

    def output(self, name: str) -> str:
        return (self.workdir / f"{name}.txt").read_text(errors="replace")

    def alive(self, name: str) -> bool:
        return self.procs[name].poll() is None

    def stop(self) -> None:
        for proc in reversed(self.procs.values()):
            if proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(10)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait(10)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def drops_logged(rig: Rig, name: str) -> int:
    return rig.output(name).count("dropped a message")


#: The valid search sent after the cases: (scene, target, start) of Table II.
CHECK_SEARCH = (1, "Apple", "kitchen-1")
RESULT_KEYS = ("success", "path_length", "found", "plans")


def simulated(log_dir: Path) -> dict[str, Any]:
    """:data:`CHECK_SEARCH` in the in-process simulator on a fresh log: what the agent, after
    the cases, must answer (its first task, as no case may start one)."""
    from objsearch.runtime.standin import in_process_search

    return in_process_search(log_dir, *CHECK_SEARCH)


def fuzz_rig(
    rig: Rig, n: int, seed: int, expected: dict[str, Any], *, settle_s: float = 20.0
) -> tuple[FuzzCounts, Any]:
    """Run ``n`` cases against ``rig``, then one valid reset and search (:data:`CHECK_SEARCH`);
    returns the tally and the search's result (None if it got none). ``served`` counts the
    search if its result equals ``expected`` (:func:`simulated`); otherwise it is ``wrong``.

    ``crashed`` counts processes that died or printed a traceback; a drop whose log line never
    appeared (within ``settle_s``) is a ``wrong`` case."""
    from objsearch.runtime.backends import open_transport
    from objsearch.runtime.client import AgentClient

    counts = FuzzCounts()
    config = rig.config()
    node = Node(open_transport(config.transport))
    result: Any = None
    try:
        with AgentClient(config) as client:
            # Both ends up and matched before the first case.
            client.reset_sim(None, "kitchen-1", timeout_s=60)
            client.find("Unicorn", timeout_s=60)
            fuzzer = Fuzzer(node, config, seed)
            time.sleep(0.5)
            fuzzer.run(n, counts)
            scene, target, start = CHECK_SEARCH
            reset = client.reset_sim(scene, start, timeout_s=30)
            if reset.get("ok"):
                result = client.find(
                    target,
                    start=start,
                    scene=scene,
                    timeout_s=90,
                    not_before_ns=int(reset["stamp_ns"]),
                )
    finally:
        node.close()
    if (
        result is not None
        and result.get("ok")
        and all(result.get(k) == v for k, v in expected.items())
    ):
        counts.served += 1
    else:
        counts.wrong.append(f"the valid search after the cases: {result}, expected {expected}")
    deadline = time.monotonic() + settle_s
    for name in ("agent", "robot"):
        while drops_logged(rig, name) < counts.drops_by[name] and time.monotonic() < deadline:
            time.sleep(0.1)
        logged = drops_logged(rig, name)
        if logged != counts.drops_by[name]:
            counts.wrong.append(f"{name}: {logged} drops logged, {counts.drops_by[name]} sent")
        if not rig.alive(name) or "Traceback" in rig.output(name):
            counts.crashed += 1
    return counts, result
