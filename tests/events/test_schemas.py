from __future__ import annotations

import copy
import dataclasses
import json
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated, Any

import msgspec
import pytest
from jsonschema import Draft202012Validator

from objsearch.agent.catalogue import CATALOGUE, STORE
from objsearch.events import EventStoreError, InvalidEventError, SchemaRegistry, schema_writer
from objsearch.events.catalogue import Catalogue
from objsearch.events.schemas import schema_id

from .payloads import EXAMPLES, LATEST, OLD_EXAMPLES

REPO = Path(__file__).resolve().parents[2]
SCHEMA_DIR = REPO / "events" / "schema"


@pytest.fixture(scope="module")
def registry() -> SchemaRegistry:
    return STORE.registry


def test_registry_knows_every_documented_type(registry: SchemaRegistry) -> None:
    assert set(registry.types) == set(EXAMPLES)
    assert {t: registry.latest_version(t) for t in registry.types} == LATEST
    assert registry.versions("moved") == (1,)
    assert registry.versions("detection") == (1, 2, 3)


@pytest.mark.parametrize("event_type", sorted(EXAMPLES))
def test_example_payloads_are_valid(registry: SchemaRegistry, event_type: str) -> None:
    registry.validate(event_type, LATEST[event_type], EXAMPLES[event_type])


@pytest.mark.parametrize("key", sorted(OLD_EXAMPLES))
def test_old_example_payloads_are_valid_for_their_version_only(
    registry: SchemaRegistry, key: tuple[str, int]
) -> None:
    event_type, version = key
    registry.validate(event_type, version, OLD_EXAMPLES[key])
    with pytest.raises(InvalidEventError):
        registry.validate(event_type, LATEST[event_type], OLD_EXAMPLES[key])


@pytest.mark.parametrize("event_type", sorted(EXAMPLES))
def test_every_required_field_is_enforced(registry: SchemaRegistry, event_type: str) -> None:
    for field in EXAMPLES[event_type]:
        payload = {k: v for k, v in EXAMPLES[event_type].items() if k != field}
        with pytest.raises(InvalidEventError, match=f"'{field}' is a required property"):
            registry.validate(event_type, LATEST[event_type], payload)


def test_message_names_type_version_path_and_reason(registry: SchemaRegistry) -> None:
    payload = dict(EXAMPLES["task_started"], target=3)
    with pytest.raises(InvalidEventError) as info:
        registry.validate("task_started", 2, payload)
    assert str(info.value) == (
        "invalid task_started v2 event: payload.target: 3 is not of type 'string'"
    )
    err = info.value
    assert (err.event_type, err.version, err.path) == ("task_started", 2, "payload.target")
    assert err.reason == "3 is not of type 'string'"


@pytest.mark.parametrize(
    ("event_type", "change", "path", "reason"),
    [
        ("scene_graph_seeded", ("values", 1, "rel", 1.5), "payload.values[1].rel", "maximum of 1"),
        (
            "plan_computed",
            ("candidates", 0, "viewpoint", [1.0]),
            "payload.candidates[0].viewpoint",
            "too short",
        ),
        ("moved", ("end", "yaw", "north"), "payload.end.yaw", "not of type 'number'"),
        ("moved", ("metres", -0.1), "payload.metres", "less than the minimum of 0"),
        ("run_started", ("method", "greedy"), "payload.method", "is not one of"),
        ("view_taken", ("reason", "peek"), "payload.reason", "is not one of"),
        ("detection", ("position", [1, 2]), "payload.position", "too short"),
        ("task_started", ("scene", 1.5), "payload.scene", "not of type 'integer', 'null'"),
        ("task_ended", ("success", "yes"), "payload.success", "not of type 'boolean'"),
    ],
)
def test_nested_errors_point_at_the_field(
    registry: SchemaRegistry, event_type: str, change: tuple[Any, ...], path: str, reason: str
) -> None:
    payload = copy.deepcopy(EXAMPLES[event_type])
    target: Any = payload
    *keys, last, value = change
    for key in keys:
        target = target[key]
    target[last] = value
    with pytest.raises(InvalidEventError, match=re.escape(f"event: {path}: ")) as info:
        registry.validate(event_type, LATEST[event_type], payload)
    assert info.value.path == path
    assert reason in str(info.value)


def test_unknown_fields_are_refused(registry: SchemaRegistry) -> None:
    payload = dict(EXAMPLES["search_failed"], detail="x")
    with pytest.raises(InvalidEventError, match=r"payload: Additional properties .*'detail'"):
        registry.validate("search_failed", 1, payload)
    pose = dict(EXAMPLES["container_opened"]["pose"], z=0.0)
    with pytest.raises(InvalidEventError, match=r"payload.pose: Additional properties"):
        registry.validate("container_opened", 1, dict(EXAMPLES["container_opened"], pose=pose))


def test_several_problems_are_counted(registry: SchemaRegistry) -> None:
    with pytest.raises(InvalidEventError, match=r"\(and 2 more problem\(s\)\)"):
        registry.validate("task_ended", 1, {"target": 1, "success": 2, "path_length": "3"})


def test_unknown_type_lists_the_known_ones(registry: SchemaRegistry) -> None:
    with pytest.raises(InvalidEventError, match=r"unknown event type 'teleported'; known types: "):
        registry.validate("teleported", 1, {})
    with pytest.raises(InvalidEventError) as info:
        registry.latest_version("teleported")
    assert all(t in str(info.value) for t in EXAMPLES)


def test_unknown_version_lists_the_known_ones(registry: SchemaRegistry) -> None:
    with pytest.raises(InvalidEventError, match=r"unknown version 2 of event type 'moved'; .*: 1"):
        registry.validate("moved", 2, EXAMPLES["moved"])


def test_schema_returns_a_copy(registry: SchemaRegistry) -> None:
    registry.schema("moved", 1)["properties"].clear()
    registry.validate("moved", 1, EXAMPLES["moved"])
    with pytest.raises(InvalidEventError):
        registry.validate("moved", 1, {})


# --- the schema files themselves ---------------------------------------------------------------


def test_the_committed_schema_files_are_written_from_the_records() -> None:
    """The records are the one definition: every file is exactly what the writer makes of its
    record, and no file is there without one."""
    stale = schema_writer.differences(CATALOGUE, SCHEMA_DIR)
    assert not stale, (
        "events/schema/ is not what the records in agent/catalogue.py say; regenerate it with "
        "`make schemas` (python -m objsearch.agent.schema_files) and commit the result:\n  "
        + "\n  ".join(stale)
    )
    released = schema_writer.released(CATALOGUE)
    assert len(list(SCHEMA_DIR.glob("*.json"))) == len(CATALOGUE.records) + len(released)


def test_released_versions_are_kept_byte_for_byte_and_never_lost(tmp_path: Path) -> None:
    """An old version no record defines is its released file: written as the folder holds it,
    and a catalogue whose folder lost one says which, rather than drop the version."""
    released = schema_writer.released(CATALOGUE)
    assert ("detection", 1) in released and ("run_started", 4) in released
    schema_writer.write(CATALOGUE, tmp_path)
    for event_type, version in released:
        name = schema_writer.file_name(event_type, version)
        assert (tmp_path / name).read_bytes() == (SCHEMA_DIR / name).read_bytes()
    (tmp_path / "view_taken.v1.json").unlink()
    lost = dataclasses.replace(CATALOGUE, schemas=tmp_path)
    with pytest.raises(schema_writer.SchemaWriterError, match=r"view_taken\.v1\.json: a released"):
        schema_writer.render(lost)


def test_the_writer_reports_and_mends_a_stale_folder(tmp_path: Path) -> None:
    schema_writer.write(CATALOGUE, tmp_path)
    assert schema_writer.differences(CATALOGUE, tmp_path) == []
    (tmp_path / "moved.v1.json").write_text("{}")
    (tmp_path / "search_failed.v1.json").unlink()
    (tmp_path / "teleported.v1.json").write_text("{}")
    assert schema_writer.differences(CATALOGUE, tmp_path) == [
        "moved.v1.json: differs from its record",
        "search_failed.v1.json: missing",
        "teleported.v1.json: no record defines it",
    ]
    assert schema_writer.write(CATALOGUE, tmp_path) == [
        "moved.v1.json",
        "search_failed.v1.json",
        "teleported.v1.json",
    ]
    assert schema_writer.differences(CATALOGUE, tmp_path) == []


class _Defaulted(msgspec.Struct, frozen=True):
    a: int = 0


class _Either(msgspec.Struct, frozen=True):
    a: int | str


class _Pattern(msgspec.Struct, frozen=True):
    a: Annotated[str, msgspec.Meta(pattern="^x$")]


@pytest.mark.parametrize(
    ("record", "message"),
    [
        (_Defaulted, "ping v1.a: has a default"),
        (_Either, r"ping v1.a: only 'X \| None' unions"),
        (_Pattern, r"ping v1.a: msgspec.Meta\(pattern=...\) is not translated"),
    ],
)
def test_the_writer_refuses_what_it_cannot_state(
    record: type[msgspec.Struct], message: str
) -> None:
    """A constraint the schema would not state would make the file and the record disagree."""
    catalogue = Catalogue(schemas=Path("."), records={("ping", 1): record})
    with pytest.raises(schema_writer.SchemaWriterError, match=message):
        schema_writer.render(catalogue)


def _object_schemas(node: Any) -> Iterator[dict[str, Any]]:
    if isinstance(node, dict):
        if node.get("type") == "object":
            yield node
        for value in node.values():
            yield from _object_schemas(value)
    elif isinstance(node, list):
        for value in node:
            yield from _object_schemas(value)


@pytest.mark.parametrize("path", sorted(SCHEMA_DIR.glob("*.json")), ids=lambda p: p.name)
def test_schema_files_are_closed_draft_2020_12_with_every_field_required(path: Path) -> None:
    schema = json.loads(path.read_text(encoding="utf-8"))
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    event_type, version = path.name.removesuffix(".json").split(".v")
    assert schema["$id"] == schema_id(event_type, int(version))
    Draft202012Validator.check_schema(schema)
    for obj in _object_schemas(schema):
        if "properties" not in obj:
            continue  # deliberately free-form, like run_started.params
        assert obj["additionalProperties"] is False, obj
        assert sorted(obj["required"]) == sorted(obj["properties"]), obj


def test_free_form_params_accept_anything_json(registry: SchemaRegistry) -> None:
    payload = dict(EXAMPLES["run_started"], params={"a": [1, {"b": None}], "c": "d"})
    registry.validate("run_started", 3, payload)


def test_docs_table_lists_every_type_and_field() -> None:
    doc = (REPO / "docs" / "events.md").read_text(encoding="utf-8")
    for event_type, payload in EXAMPLES.items():
        row = next((ln for ln in doc.splitlines() if ln.startswith(f"| `{event_type}`")), None)
        assert row is not None, f"docs/events.md has no table row for {event_type}"
        for field in payload:
            assert f"`{field}`" in row, f"docs/events.md row for {event_type} misses {field}"


# --- registries built from other folders (how a v2 would arrive) -------------------------------


def _write(directory: Path, name: str, schema: dict[str, Any]) -> None:
    (directory / name).write_text(json.dumps(schema), encoding="utf-8")


def _schema(event_type: str, version: int, **props: Any) -> dict[str, Any]:
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": schema_id(event_type, version),
        "type": "object",
        "additionalProperties": False,
        "required": sorted(props),
        "properties": props,
    }


def test_latest_version_is_the_highest_file(tmp_path: Path) -> None:
    _write(tmp_path, "ping.v1.json", _schema("ping", 1, a={"type": "string"}))
    _write(tmp_path, "ping.v2.json", _schema("ping", 2, b={"type": "integer"}))
    (tmp_path / "README.md").write_text("not a schema")
    registry = SchemaRegistry.from_directory(tmp_path)
    assert registry.latest_version("ping") == 2
    registry.validate("ping", 1, {"a": "x"})
    registry.validate("ping", 2, {"b": 1})
    with pytest.raises(InvalidEventError, match="invalid ping v2 event: payload"):
        registry.validate("ping", 2, {"a": "x"})


@pytest.mark.parametrize(
    ("name", "schema", "message"),
    [
        ("Ping.v1.json", _schema("ping", 1), "is not named <type>.v<version>.json"),
        ("ping.v0.json", _schema("ping", 0), "is not named"),
        ("ping.v1.json", _schema("pong", 1), r"\$id is 'urn:objsearch:events:pong:v1'"),
        ("ping.v1.json", dict(_schema("ping", 1), type=5), "not a valid JSON Schema"),
        ("ping.v1.json", dict(_schema("ping", 1), type="array"), "must have type 'object'"),
    ],
)
def test_broken_schema_folders_are_refused(
    tmp_path: Path, name: str, schema: dict[str, Any], message: str
) -> None:
    _write(tmp_path, name, schema)
    with pytest.raises(EventStoreError, match=message):
        SchemaRegistry.from_directory(tmp_path)


def test_invalid_json_schema_file_is_refused(tmp_path: Path) -> None:
    (tmp_path / "ping.v1.json").write_text("{not json")
    with pytest.raises(EventStoreError, match=r"'ping\.v1\.json' is not valid JSON"):
        SchemaRegistry.from_directory(tmp_path)


def test_the_shipped_schemas_are_not_checked_again_in_every_process() -> None:
    """The package's own schema files are checked here (above), so building the product's
    registry imports no jsonschema: a search pays for it only if a payload needs it."""
    code = (
        "import sys\n"
        "from objsearch.agent.catalogue import STORE\n"
        "from objsearch.events.store import shipped\n"
        "STORE.registry.validate('search_failed', 1, {'reason': 'r'})\n"
        "shipped().registry\n"
        "assert 'jsonschema' not in sys.modules, 'jsonschema imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
