"""Every JSON request and result the agent, its clients and the stand-in robot exchange, checked
in one place per message type.

A message from the network is untrusted: each parser below reads exactly the fields its type has,
checks each one's type and range, and raises :class:`RequestError` naming the field and why. No
other module calls ``int()``/``float()``/``str()`` on a decoded request or result. A document
that is not a JSON object, or has no usable ``id``, cannot be answered (there is nothing to
correlate an answer with) and is dropped with a log line by the caller; a document with an ``id``
and a bad field gets an error result carrying that ``id``.

==========================  ======================================================================
message                     fields
==========================  ======================================================================
find request                ``id``, ``target`` (a class name), ``start`` (label or null),
                            ``scene`` (int or null), ``not_before_ns`` (int ≥ 0 or null)
find result                 ``id``, ``ok``, ``error``, ``target``, ``task_id``, ``success``,
                            ``path_length``, ``found``, ``plans``
where request               ``id``, ``target`` (a class name)
where result                ``id``, ``ok``, ``error``, ``answer`` (``objsearch where --format json``'s
                            object: ``target``, ``last_seen``, ``usually``, ``most_likely_now``, …)
open request (agent→robot)  ``id``, ``static_id``
open result                 ``id``, ``ok``, ``stamp_ns``, ``yaw``, ``error``
reset request (stand-in)    ``id``, ``scene`` (int or null), ``start`` (label)
reset result                ``id``, ``ok``, ``stamp_ns``, ``error``
agent heartbeat             ``agent`` (an id), ``node``, ``host`` (names), ``pid`` (int ≥ 0),
                            ``log`` (text), ``state`` (claiming|serving), ``since_ns`` (int ≥ 0),
                            ``serves`` (1-16 ROS names: its find topic, its robot's goal)
==========================  ======================================================================
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from objsearch.runtime.errors import MessageError

#: A request or result topic carries small JSON documents; anything bigger is refused unread.
MAX_DOCUMENT_BYTES = 16 * 1024
#: Correlation ids: printable ASCII without spaces, as uuid4 strings and short names are.
ID_PATTERN = re.compile(r"[!-~]{1,128}")
#: Names the agent records or forwards (targets, start labels, static object ids, errors).
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9 _./:|+-]{0,127}")
MAX_ERROR_CHARS = 4096
MAX_SCENE = 2**31 - 1
MAX_NS = 2**63 - 1


class RequestError(MessageError):
    """A request or result with a field that is missing, of the wrong type or out of range."""

    def __init__(self, what: str, field: str, problem: str) -> None:
        super().__init__(f"{what}: field {field!r} {problem}")
        self.field = field


#: Integers with more digits than this are read as :class:`HugeNumber` (no field takes them).
MAX_DIGITS = 40


@dataclass(frozen=True, slots=True)
class HugeNumber:
    """An integer literal too long to be any field's value, kept so the error can name the field
    (instead of the whole document failing to parse)."""

    digits: int

    def __repr__(self) -> str:
        return f"<an integer of {self.digits} digits>"


def _parse_int(text: str) -> int | HugeNumber:
    return int(text) if len(text) <= MAX_DIGITS else HugeNumber(len(text))


def parse_document(text: str) -> dict[str, Any]:
    """The JSON object in a request or result message. ``NaN`` and ``Infinity`` (which Python
    writes, though JSON has no such numbers) are read as floats for the fields to refuse by name;
    deep nesting and documents over :data:`MAX_DOCUMENT_BYTES` are refused whole."""
    if len(text) > MAX_DOCUMENT_BYTES:
        raise MessageError(
            f"a JSON document of {len(text)} characters (at most {MAX_DOCUMENT_BYTES})"
        )
    try:
        doc = json.loads(text, parse_constant=float, parse_int=_parse_int)
    except (ValueError, RecursionError) as exc:
        raise MessageError(f"expected a JSON object, got {text[:80]!r}: {exc}") from None
    if not isinstance(doc, dict):
        raise MessageError(f"expected a JSON object, got {type(doc).__name__} {text[:80]!r}")
    return doc


def request_id(doc: Mapping[str, Any]) -> str:
    """The correlation id; a message without a usable one cannot be answered."""
    rid = doc.get("id")
    if not isinstance(rid, str) or not ID_PATTERN.fullmatch(rid):
        raise MessageError(f"no usable 'id' (a string of 1-128 printable characters): {_show(rid)}")
    return rid


def _show(value: Any) -> str:
    text = repr(value)
    return f"{text[:60]}… ({len(text)} characters)" if len(text) > 64 else text


class _Fields:
    """One document's fields, each read once; unknown fields are an error (a typo, or a client
    speaking another version, should be told rather than silently ignored)."""

    def __init__(self, doc: Mapping[str, Any], what: str, known: set[str]) -> None:
        self.doc = doc
        self.what = what
        unknown = sorted(str(k) for k in doc if k not in known)
        if unknown:
            raise RequestError(what, unknown[0], f"is not a field (known: {sorted(known)})")

    def fail(self, key: str, problem: str) -> RequestError:
        return RequestError(self.what, key, f"{problem}, got {_show(self.doc.get(key))}")

    def name(self, key: str, *, optional: bool = False) -> str | None:
        value = self.doc.get(key)
        if value is None and optional:
            return None
        if not isinstance(value, str) or not NAME_PATTERN.fullmatch(value):
            null = " or null" if optional else ""
            raise self.fail(
                key,
                f"must be a name (a letter or digit, then letters, digits, spaces or _./:|+-; at most 128 characters){null}",
            )
        return value

    def int(self, key: str, low: int, high: int, *, optional: bool = False) -> int | None:
        value = self.doc.get(key)
        if value is None and optional:
            return None
        if not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high:
            null = " or null" if optional else ""
            raise self.fail(key, f"must be an integer in {low}..{high}{null}")
        return value

    def number(self, key: str) -> float:
        value = self.doc.get(key)
        if (
            not isinstance(value, int | float)
            or isinstance(value, bool)
            or not math.isfinite(value)
        ):
            raise self.fail(key, "must be a finite number")
        return float(value)

    def bool(self, key: str) -> bool:
        value = self.doc.get(key)
        if not isinstance(value, bool):
            raise self.fail(key, "must be true or false")
        return value

    def error(self) -> str | None:
        value = self.doc.get("error")
        if value is None:
            return None
        if not isinstance(value, str) or len(value) > MAX_ERROR_CHARS:
            raise self.fail("error", f"must be a string of at most {MAX_ERROR_CHARS} characters")
        return value


# -- find: client → agent --------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class FindRequest:
    id: str
    target: str
    start: str | None = None
    scene: int | None = None
    not_before_ns: int = 0

    def to_json(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "target": self.target,
            "start": self.start,
            "scene": self.scene,
            "not_before_ns": self.not_before_ns,
        }


FIND_FIELDS = {"id", "target", "start", "scene", "not_before_ns"}


def parse_find_request(doc: Mapping[str, Any]) -> FindRequest:
    """Types and ranges only: whether ``target`` is a known class is the agent's to say."""
    f = _Fields(doc, "find request", FIND_FIELDS)
    target = f.name("target")
    assert target is not None
    return FindRequest(
        id=request_id(doc),
        target=target,
        start=f.name("start", optional=True),
        scene=f.int("scene", 0, MAX_SCENE, optional=True),
        not_before_ns=f.int("not_before_ns", 0, MAX_NS, optional=True) or 0,
    )


FIND_RESULT_FIELDS = {
    "id",
    "ok",
    "error",
    "target",
    "task_id",
    "success",
    "path_length",
    "found",
    "plans",
}


def check_find_result(doc: Mapping[str, Any]) -> dict[str, Any]:
    """A find result as the agent sends it (``ok`` false: ``error`` says why)."""
    f = _Fields(doc, "find result", FIND_RESULT_FIELDS)
    request_id(doc)
    ok = f.bool("ok")
    f.error()
    for key in ("target", "task_id"):
        if key in doc:
            f.name(key, optional=True)
    if not ok:
        if not isinstance(doc.get("error"), str):
            raise f.fail("error", "must say why when ok is false")
        return dict(doc)
    f.bool("success")
    f.number("path_length")
    f.name("found", optional=True)
    plans = doc.get("plans")
    if not isinstance(plans, list) or not all(
        isinstance(p, list)
        and len(p) == 2
        and isinstance(p[0], str)
        and isinstance(p[1], list)
        and all(isinstance(s, str) for s in p[1])
        for p in plans
    ):
        raise f.fail("plans", "must be a list of [room, [stop, …]]")
    return dict(doc)


# -- where: client → agent ------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class WhereRequest:
    id: str
    target: str


def parse_where_request(doc: Mapping[str, Any]) -> WhereRequest:
    """Types only: whether ``target`` is a class the agent's memory knows is the agent's to say."""
    f = _Fields(doc, "where request", {"id", "target"})
    target = f.name("target")
    assert target is not None
    return WhereRequest(request_id(doc), target)


#: What an answer must hold (agent/where.py writes them; the rest is passed on as sent).
WHERE_ANSWER_KEYS = ("target", "tasks", "last_seen", "usually", "most_likely_now")


def check_where_result(doc: Mapping[str, Any]) -> dict[str, Any]:
    """A where result as the agent sends it (``ok`` false: ``error`` says why)."""
    f = _Fields(doc, "where result", {"id", "ok", "error", "answer"})
    request_id(doc)
    if not f.bool("ok"):
        if not isinstance(f.error(), str):
            raise f.fail("error", "must say why when ok is false")
        return dict(doc)
    answer = doc.get("answer")
    if not isinstance(answer, dict) or any(k not in answer for k in WHERE_ANSWER_KEYS):
        raise f.fail("answer", f"must be an object with {', '.join(WHERE_ANSWER_KEYS)}")
    for key in ("last_seen", "usually"):
        if answer[key] is not None and not isinstance(answer[key], dict):
            raise f.fail("answer", f"must hold {key!r} as an object or null")
    if not isinstance(answer["most_likely_now"], list):
        raise f.fail("answer", "must hold 'most_likely_now' as a list")
    return dict(doc)


# -- open: agent → robot ---------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class OpenRequest:
    id: str
    static_id: str


def parse_open_request(doc: Mapping[str, Any]) -> OpenRequest:
    f = _Fields(doc, "open request", {"id", "static_id"})
    static_id = f.name("static_id")
    assert static_id is not None
    return OpenRequest(request_id(doc), static_id)


@dataclass(frozen=True, slots=True)
class OpenResult:
    id: str
    ok: bool
    stamp_ns: int = 0
    yaw: float = 0.0
    error: str | None = None


def parse_open_result(doc: Mapping[str, Any]) -> OpenResult:
    f = _Fields(doc, "open result", {"id", "ok", "stamp_ns", "yaw", "error"})
    rid = request_id(doc)
    if not f.bool("ok"):
        return OpenResult(rid, False, error=f.error() or "no reason given")
    stamp = f.int("stamp_ns", 0, MAX_NS)
    assert stamp is not None
    return OpenResult(rid, True, stamp, f.number("yaw"), f.error())


# -- reset: tests and demos → the stand-in robot ---------------------------------------------


@dataclass(frozen=True, slots=True)
class ResetRequest:
    id: str
    start: str
    scene: int | None = None


def parse_reset_request(doc: Mapping[str, Any]) -> ResetRequest:
    f = _Fields(doc, "reset request", {"id", "scene", "start"})
    start = f.name("start")
    assert start is not None
    return ResetRequest(request_id(doc), start, f.int("scene", 0, MAX_SCENE, optional=True))


def check_reset_result(doc: Mapping[str, Any]) -> dict[str, Any]:
    f = _Fields(doc, "reset result", {"id", "ok", "stamp_ns", "error"})
    request_id(doc)
    if f.bool("ok"):
        f.int("stamp_ns", 0, MAX_NS)
    elif f.error() is None:
        raise f.fail("error", "must say why when ok is false")
    return dict(doc)


# -- heartbeats: agent ↔ agent (runtime/oneagent.py) -------------------------------------------

#: A ROS name (a topic or an action): absolute or relative, tokens of letters, digits and ``_``.
ROS_NAME_PATTERN = re.compile(r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")
#: Text shown to an operator (a log folder): no control characters, at most this many.
MAX_TEXT_CHARS = 1024
_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")
HEARTBEAT_STATES = ("claiming", "serving")
MAX_SERVES = 16


@dataclass(frozen=True, slots=True)
class Heartbeat:
    """What an agent says about itself, several times a second, to the other agents on its
    graph: who it is, whether it is still claiming its robot or serving it, since when, and
    which names it serves (its find topic and where it sends its robot's goals)."""

    agent: str
    node: str
    host: str
    pid: int
    log: str
    state: str
    since_ns: int
    serves: tuple[str, ...]

    def key(self) -> tuple[int, str]:
        """The order two agents claiming one robot agree on: the earlier claim, then the id."""
        return (self.since_ns, self.agent)

    def to_json(self) -> dict[str, Any]:
        return {
            "agent": self.agent,
            "node": self.node,
            "host": self.host,
            "pid": self.pid,
            "log": self.log,
            "state": self.state,
            "since_ns": self.since_ns,
            "serves": list(self.serves),
        }


HEARTBEAT_FIELDS = {"agent", "node", "host", "pid", "log", "state", "since_ns", "serves"}


def parse_heartbeat(doc: Mapping[str, Any]) -> Heartbeat:
    f = _Fields(doc, "agent heartbeat", HEARTBEAT_FIELDS)
    agent = doc.get("agent")
    if not isinstance(agent, str) or not ID_PATTERN.fullmatch(agent):
        raise f.fail("agent", "must be an id (a string of 1-128 printable characters)")
    node, host = f.name("node"), f.name("host")
    pid, since_ns = f.int("pid", 0, MAX_SCENE), f.int("since_ns", 0, MAX_NS)
    assert node is not None and host is not None and pid is not None and since_ns is not None
    log = doc.get("log")
    if not isinstance(log, str) or len(log) > MAX_TEXT_CHARS or _CONTROL.search(log):
        raise f.fail("log", f"must be text of at most {MAX_TEXT_CHARS} characters")
    state = doc.get("state")
    if state not in HEARTBEAT_STATES:
        raise f.fail("state", f"must be one of {', '.join(HEARTBEAT_STATES)}")
    serves = doc.get("serves")
    if (
        not isinstance(serves, list)
        or not 1 <= len(serves) <= MAX_SERVES
        or not all(
            isinstance(s, str) and len(s) <= 256 and ROS_NAME_PATTERN.fullmatch(s) for s in serves
        )
    ):
        raise f.fail("serves", f"must be a list of 1-{MAX_SERVES} ROS names")
    return Heartbeat(agent, node, host, pid, log, state, since_ns, tuple(serves))
