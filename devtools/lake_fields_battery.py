"""The optional-fields battery: every optional field of every event schema, null and absent,
through ``objsearch lake add`` → read back → ``replay`` and ``where``, each held to "the lake
answers as the log did".

A field is optional where its schema (``events/schema/*.json``, written from the payload records
of ``agent/catalogue.py``) lets it be null (``[T, "null"]``, ``oneOf [null, T]``) or leaves it out
of ``required``, at any depth (inside a nested object, or an array's items). For each schema file
(every type, every version) and each such field, a variant makes one payload of that type and
version (:func:`example_payload`: every field present) with the field null, and another with it
absent. Absent is not valid for a field the schema requires (every field of the catalogue's
records is required; ``[T, "null"]`` ones are null, not absent): such a record is written by no
append, but a log from another writer can hold one, and ``read_log`` checks envelopes and
checksums, not payloads. The variant event goes into a real search's log (``objsearch search``
from the bundled data) in place of the first event of its type and version, or before its last
event; the log is written record by record, checksums chained. Then, in process:

* ``objsearch lake add LOG`` into a fresh lake;
* the run's events read back (:meth:`TableLake.read_events`), compared with ``read_log``'s;
* ``objsearch replay`` and ``objsearch where Cup`` of the lake run and of the log.

Each variant gets one verdict, the worst of:

* **clear error** — ``lake add`` refused the log with ``objsearch: error:`` (nothing stored);
* **unchanged** — every command answered from the lake as from the log (exit status and
  output), and the events read back equal the log's (an absent field reads back as null: the
  table has a column for it; they are equal when the log's event reads it as null too);
* **traceback** — a traceback, or an exit status other than 0, 1 and 2, from any command;
* **silent change** — an answer or an event from the lake differs from the log's, and nothing
  said so;
* **loss** — the lake took the run and then refused it or gave fewer events (a healthy run
  that cannot be read back: issue 43, item 1).

``benchmarks/lake_fields.py`` runs every variant and prints the counts;
``tests/test_lake_fields_battery.py`` runs some of each kind in the suite.
"""

from __future__ import annotations

import copy
import json
import shutil
from collections import Counter
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from devtools.cli_battery import BatteryOutcome, run_in_process
from objsearch.events import Event, read_log
from objsearch.events.envelope import deterministic_event_id
from objsearch.events.lake import TableLake, TableLakeError
from objsearch.events.log_files import LOG_FORMAT, LogMeta, LogPosition, write_durable
from objsearch.events.record import encode_record
from objsearch.events.store import Store
from objsearch.product import STORE

COLUMNS = ("clear error", "unchanged", "traceback", "silent change", "loss")
#: The worst verdict first (a variant gets the first that applies).
_WORST = ("traceback", "loss", "silent change", "clear error", "unchanged")
RUN = "variant"
ROBOT = "r"
#: ``where``'s time of the week: fixed, so the log's answer and the lake's compare (the default
#: is the local clock, which moves between the two).
AT = "mon 09:00"

How = Literal["null", "absent"]


@dataclass(frozen=True, slots=True)
class Variant:
    """One payload of ``event_type`` v``version`` with the field at ``path`` null or absent."""

    event_type: str
    version: int
    path: str  # "clock", "relations.prior_strength", "detections[0].position"
    how: How
    payload: Mapping[str, Any]

    @property
    def name(self) -> str:
        return f"{self.event_type} v{self.version} {self.path} {self.how}"


# -- the variants -------------------------------------------------------------------------------


def _resolve(node: Mapping[str, Any], root: Mapping[str, Any]) -> Mapping[str, Any]:
    while "$ref" in node:
        node = root["$defs"][str(node["$ref"]).removeprefix("#/$defs/")]
    return node


def _nullable(node: Mapping[str, Any], root: Mapping[str, Any]) -> bool:
    node = _resolve(node, root)
    kinds = node.get("type")
    if isinstance(kinds, list) and "null" in kinds:
        return True
    return any(_resolve(o, root).get("type") == "null" for o in node.get("oneOf", ()))


def _value(node: Mapping[str, Any], root: Mapping[str, Any]) -> Any:
    """A valid, non-null value of the schema ``node``: every field of an object present, an
    array of two items (or its fixed length)."""
    node = _resolve(node, root)
    if "oneOf" in node:
        options = [o for o in node["oneOf"] if _resolve(o, root).get("type") != "null"]
        return _value(options[0], root)
    if "enum" in node:
        return node["enum"][0]
    kinds = node.get("type")
    kind = next(k for k in kinds if k != "null") if isinstance(kinds, list) else kinds
    if kind == "string":
        return "0000abcd"  # a word no reader parses as more (a chain, a name, a class)
    if kind == "boolean":
        return True
    if kind in ("integer", "number"):
        low = node.get("minimum")
        above = node.get("exclusiveMinimum")
        value: float = low if low is not None else (above + 1 if above is not None else 1)
        if node.get("maximum") is not None:
            value = min(value, node["maximum"])
        return int(value) if kind == "integer" else float(value) + 0.25 * (value == 0)
    if kind == "array":
        n = max(node.get("minItems", 0), min(2, node.get("maxItems", 2)))
        return [_value(node.get("items", {}), root) for _ in range(n)]
    if kind == "object":
        props = node.get("properties")
        if not props:  # free-form
            return {"fov_deg": 90, "nested": {"ok": [1, 2]}}
        return {name: _value(sub, root) for name, sub in props.items()}
    raise ValueError(f"no example value for schema node {dict(node)!r}")


def example_payload(schema: Mapping[str, Any]) -> dict[str, Any]:
    """A payload valid under ``schema`` with every field present and not null."""
    value = _value(schema, schema)
    assert isinstance(value, dict)
    return value


def _optional(
    node: Mapping[str, Any], root: Mapping[str, Any], path: str
) -> Iterator[tuple[str, How]]:
    """The optional fields under ``node`` (paths into a payload :func:`_value` made)."""
    node = _resolve(node, root)
    if "oneOf" in node:
        for option in node["oneOf"]:
            if _resolve(option, root).get("type") != "null":
                yield from _optional(option, root, path)
        return
    kinds = node.get("type")
    kinds = kinds if isinstance(kinds, list) else [kinds]
    if "object" in kinds and node.get("properties"):
        required = set(node.get("required", ()))
        for name, sub in node["properties"].items():
            at = f"{path}.{name}" if path else name
            if _nullable(sub, root):
                yield at, "null"
            # absent: what a record may hold though no append writes it (see the module)
            if name not in required or _nullable(sub, root):
                yield at, "absent"
            yield from _optional(sub, root, at)
    elif "array" in kinds:
        yield from _optional(node.get("items", {}), root, f"{path}[0]")


def _set(payload: dict[str, Any], path: str, how: How) -> None:
    """Make the field at ``path`` null or absent (``a.b``, ``a[0].b``)."""
    parts = path.replace("[", ".[").split(".")
    target: Any = payload
    for part in parts[:-1]:
        target = target[int(part[1:-1])] if part.startswith("[") else target[part]
    last = parts[-1]
    if how == "null":
        target[last] = None
    else:
        del target[last]


def variants(
    store: Store = STORE, real: Mapping[tuple[str, int], Mapping[str, Any]] | None = None
) -> list[Variant]:
    """Every optional field of every schema of ``store``, null and absent; each made from the
    payload of ``real`` of its type and version if there is one (a real search's: the fold
    then meets values it knows), else from :func:`example_payload`."""
    out = []
    registry = store.registry
    for event_type in sorted(registry.types):
        for version in range(1, registry.latest_version(event_type) + 1):
            schema = registry.schema(event_type, version)
            for path, how in _optional(schema, schema, ""):
                payload = None
                if real is not None and (event_type, version) in real:
                    payload = copy.deepcopy(dict(real[event_type, version]))
                    try:
                        _set(payload, path, how)
                    except (KeyError, IndexError, TypeError):  # the path is null there
                        payload = None
                if payload is None:
                    payload = example_payload(schema)
                    _set(payload, path, how)
                out.append(Variant(event_type, version, path, how, payload))
    return out


def real_payloads(log: Path) -> dict[tuple[str, int], dict[str, Any]]:
    """The first payload of each type and version in ``log`` (as stored)."""
    out: dict[tuple[str, int], dict[str, Any]] = {}
    for e in read_log(log, upcast=False, store=STORE):
        out.setdefault((e.type, e.version), json.loads(json.dumps(dict(e.payload))))
    return out


# -- one variant through the lake ---------------------------------------------------------------


def base_log(root: Path) -> Path:
    """A real search's log (``objsearch search Cup``), made by the CLI."""
    log = root / "search-log"
    argv = ["search", "Cup", "--start", "kitchen-1", "--log", str(log), "--format", "json"]
    outcome = run_in_process(argv)
    if outcome.code != 0:
        raise RuntimeError(f"objsearch {' '.join(argv)} failed: {outcome.stderr[-2000:]}")
    return log


def write_variant_log(base: Path, variant: Variant, out: Path) -> Path:
    """``base``'s events (as stored) with the variant's event in place of the first of its
    type and version, or before the last event; written record by record (no payload check)."""
    events = list(read_log(base, upcast=False, store=STORE))
    at = next(
        (
            i
            for i, e in enumerate(events)
            if e.type == variant.event_type and e.version == variant.version
        ),
        None,
    )
    task_id = events[-1].task_id
    if at is None:
        at = len(events) - 1
        events.insert(at, events[at])
    else:
        task_id = events[at].task_id
    meta_path = base / "meta.json"
    meta = json.loads(meta_path.read_text())
    run_id = str(meta["run_id"])
    stream = events[0].stream
    rebuilt = []
    for seq, e in enumerate(events, start=1):
        fields: dict[str, Any] = {
            "event_id": deterministic_event_id(run_id, seq),
            "stream": stream,
            "seq": seq,
            "time_ns": e.time_ns,
            "recorded_at_ns": e.recorded_at_ns,
            "type": e.type,
            "version": e.version,
            "task_id": e.task_id,
            "payload": dict(e.payload),
        }
        if seq - 1 == at:
            fields |= {
                "type": variant.event_type,
                "version": variant.version,
                "task_id": task_id,
                "payload": copy.deepcopy(dict(variant.payload)),
            }
        rebuilt.append(Event(**fields))
    out.mkdir(parents=True)
    logmeta = LogMeta(LOG_FORMAT, stream, run_id)
    (out / "meta.json").write_text(
        json.dumps({"format": LOG_FORMAT, "stream": stream, "run_id": run_id})
    )
    prev, offset = logmeta.genesis, 0
    with (out / "events.log").open("wb") as f:
        for e in rebuilt:
            line = encode_record(e, prev)
            f.write(line)
            prev, offset = int(line[-9:-1], 16), offset + len(line)
    last = rebuilt[-1]
    write_durable(out, LogPosition(last.seq, offset, prev, len(rebuilt), last.time_ns))
    return out


@dataclass
class Result:
    """One variant's verdict and what the lake said that the log did not."""

    variant: Variant
    verdict: str
    why: str = ""


def _same_events(from_lake: Sequence[Event], from_log: Sequence[Event]) -> tuple[str, str] | None:
    """The verdict and why, if the events read back differ from the log's; else None."""
    if len(from_lake) < len(from_log):
        return "loss", f"{len(from_log) - len(from_lake)} events fewer"
    for a, b in zip(from_lake, from_log, strict=False):
        if a == b:
            continue
        if a.envelope_dict() != b.envelope_dict():
            return "silent change", f"seq {b.seq}: {b.envelope_dict()} -> {a.envelope_dict()}"
        lake, log = dict(a.payload), dict(b.payload)
        for key in set(lake) | set(log):
            if lake.get(key) != log.get(key) or (key not in lake):
                was, got = log.get(key, "<absent>"), lake.get(key, "<absent>")
                return "silent change", f"seq {b.seq} {b.type}.{key}: {was!r} -> {got!r}"
    if len(from_lake) != len(from_log):
        return "silent change", f"{len(from_lake) - len(from_log)} events more"
    return None


def run_variant(variant: Variant, base: Path, work: Path) -> Result:
    """One variant through ``lake add`` → read back → ``replay`` / ``where`` (see the module)."""
    log = write_variant_log(base, variant, work / "log")
    lake = work / "lake"
    outcomes: list[BatteryOutcome] = []

    def cli(argv: list[str]) -> BatteryOutcome:
        outcome = run_in_process(argv)
        outcomes.append(outcome)
        return outcome

    def worst(*found: tuple[str, str]) -> Result:
        verdicts = dict(found)
        for name in _WORST:
            if name in verdicts:
                return Result(variant, name, verdicts[name])
        return Result(variant, "unchanged")

    added = cli(["lake", "add", str(log), "--robot", ROBOT, "--run", RUN, "--lake", str(lake)])
    if added.verdict == "traceback" or added.code not in (0, 2):
        return worst(("traceback", f"lake add: {added.stderr[-600:]}"))
    if added.code == 2:
        return worst(("clear error", f"lake add: {added.stderr.strip()[-300:]}"))
    found: list[tuple[str, str]] = []
    try:
        table_lake = TableLake(lake, store=STORE)
        (run,) = table_lake.runs()
        lake_events = table_lake.read_events(run)
    except TableLakeError as exc:
        return worst(("loss", f"read back: {exc}"))
    except Exception as exc:
        return worst(("traceback", f"read back: {exc!r}"))
    try:
        log_events = list(read_log(log, store=STORE))
    except Exception as exc:  # the log itself does not read: nothing to compare with
        log_events = []
        found.append(("clear error", f"the log does not read: {exc}"))
    if log_events:
        differs = _same_events(lake_events, log_events)
        if differs is not None:
            found.append(differs)
    for command in (
        ["replay", "--format", "json", "--all"],
        ["where", "Cup", "--at", AT, "--format", "json"],
    ):
        from_log = cli([*command, str(log), "--no-progress"])
        from_lake = cli([*command, str(lake), "--run", RUN, "--no-progress"])
        name = command[0]
        for outcome in (from_log, from_lake):
            if outcome.verdict == "traceback" or outcome.code not in (0, 1, 2):
                found.append(("traceback", f"{name}: {outcome.stderr[-600:]}"))
        if from_lake.code == 2 and from_log.code != 2:
            found.append(
                ("loss", f"{name} refused the lake run: {from_lake.stderr.strip()[-300:]}")
            )
        elif (from_lake.code, from_lake.stdout) != (from_log.code, from_log.stdout):
            found.append(("silent change", f"{name} answered otherwise from the lake"))
    return worst(*found)


@dataclass
class Report:
    tried: int = 0
    counts: Counter[str] = field(default_factory=Counter)
    by_type: dict[str, dict[str, int]] = field(default_factory=dict)
    flagged: list[str] = field(default_factory=list)
    results: list[Result] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not any(self.counts[c] for c in ("traceback", "silent change", "loss"))


def run_battery(
    work: Path,
    *,
    choose: Callable[[list[Variant]], Sequence[Variant]] | None = None,
    progress: Callable[[Result], None] | None = None,
) -> Report:
    """The variants (:func:`variants` of a real search's log; those ``choose`` picks) through the
    lake (see the module), in folders under ``work``."""
    work.mkdir(parents=True, exist_ok=True)
    base = base_log(work / "base")
    every = variants(STORE, real_payloads(base))
    chosen = every if choose is None else choose(every)
    report = Report()
    for i, variant in enumerate(chosen):
        folder = work / f"v{i:04d}"
        try:
            result = run_variant(variant, base, folder)
        finally:
            shutil.rmtree(folder, ignore_errors=True)
        report.tried += 1
        report.counts[result.verdict] += 1
        row = report.by_type.setdefault(
            f"{variant.event_type} ({variant.how})", {"tried": 0, **dict.fromkeys(COLUMNS, 0)}
        )
        row["tried"] += 1
        row[result.verdict] += 1
        report.results.append(result)
        if result.verdict in ("traceback", "silent change", "loss"):
            report.flagged.append(f"{variant.name}: {result.verdict}: {result.why}")
        if progress is not None:
            progress(result)
    return report


__all__ = [
    "COLUMNS",
    "Report",
    "Result",
    "Variant",
    "example_payload",
    "run_battery",
    "run_variant",
    "variants",
    "write_variant_log",
]
