"""What the lake's tables are made of: typed columns from the schemas, every event upcast; and the
sealed-log rule of adding a log. The fleet lake's commits, replace, idempotency, damage and
readers: test_lake_table*.py and the contract (contract/)."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import EventLog, read_log
from objsearch.events.arrow import event_schema, events_to_tables
from objsearch.events.lake import LakeError, TableLake, add_log

from .lake_logs import small_log
from .payloads import EXAMPLES


def test_every_type_has_typed_columns_and_no_json_text_but_params() -> None:
    for event_type in STORE.registry.types:
        schema = event_schema(event_type, STORE)
        assert schema.names[:7] == [
            "event_id",
            "stream",
            "seq",
            "time_ns",
            "recorded_at_ns",
            "version",
            "task_id",
        ]
        for field in schema:
            if pa.types.is_string(field.type) and (event_type, field.name) == (
                "run_started",
                "params",
            ):
                continue
            assert set(EXAMPLES[event_type]) | set(schema.names[:7]) >= {field.name}
    detection = event_schema("detection", STORE)
    assert detection.field("support").type == pa.struct(
        [("static_id", pa.string()), ("static_class", pa.string()), ("at", pa.bool_())]
    )
    assert detection.field("position").type == pa.list_(pa.float64())
    assert event_schema("moved", STORE).field("start").type == pa.struct(
        [("x", pa.float64()), ("y", pa.float64()), ("yaw", pa.float64())]
    )
    assert event_schema("task_started", STORE).field("scene").type == pa.int64()


def test_tables_hold_every_event_upcast(tmp_path: Path) -> None:
    tables = events_to_tables(read_log(small_log(tmp_path), store=STORE), STORE)
    assert sum(t.num_rows for t in tables.values()) == len(EXAMPLES) + 4
    detections = tables["detection"].to_pylist()
    assert [d["version"] for d in detections] == [3, 3]
    assert detections[1]["support"] == EXAMPLES["detection"]["support"]
    assert tables["run_started"].column("params").to_pylist() == [
        '{"fov_deg":90,"nested":{"ok":[1,2]}}'
    ]


def test_a_log_being_written_is_not_added(tmp_path: Path) -> None:
    log = small_log(tmp_path / "log")
    with EventLog.open(log, "run-a", store=STORE), pytest.raises(LakeError, match="being written"):
        add_log(log, TableLake(tmp_path / "lake", store=STORE), robot="r")
    assert not (tmp_path / "lake").exists()
