"""The Parquet lake: typed columns from the schemas, atomic and idempotent commits, any reader."""

from __future__ import annotations

from pathlib import Path

import duckdb
import polars as pl
import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import EventLog, read_log
from objsearch.events.arrow import event_schema, events_to_tables
from objsearch.events.derived import DERIVED_DIR, derived_tables
from objsearch.events.lake import ROW_GROUP_ROWS, Lake, LakeError, compact_log
from objsearch.events.sql import connect

from .lake_logs import V1_LOG, small_log
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
    assert [d["version"] for d in detections] == [2, 2]
    assert detections[1]["support"] == EXAMPLES["detection"]["support"]
    assert tables["run_started"].column("params").to_pylist() == [
        '{"fov_deg":90,"nested":{"ok":[1,2]}}'
    ]


def test_compact_commits_a_run_any_parquet_reader_can_read(tmp_path: Path) -> None:
    lake = Lake(tmp_path / "lake", store=STORE)
    info = compact_log(small_log(tmp_path / "log"), lake, robot="r2d2")
    assert (info.robot, info.date, info.run) == ("r2d2", "2023-11-14", "run-a")
    assert info.path == tmp_path / "lake" / "robot=r2d2" / "date=2023-11-14" / "run=run-a"
    assert not list((tmp_path / "lake" / ".staging").iterdir())

    frame = pl.scan_parquet(
        str(tmp_path / "lake" / "**" / "search_failed.parquet"), hive_partitioning=True
    ).collect()
    assert frame["reason"].to_list() == ["all candidates visited", "r0", "r1", "r2"]
    assert set(frame["robot"].to_list()) == {"r2d2"}
    dataset = ds.dataset(info.path / "detection.parquet")
    assert dataset.to_table().column("support").type.num_fields == 3
    con = connect(lake)
    assert con.execute("SELECT count(*) FROM events").fetchone() == (len(EXAMPLES) + 4,)
    assert con.execute("SELECT robot, date::VARCHAR, run FROM task_ended").fetchall() == [
        ("r2d2", "2023-11-14", "run-a")
    ]


def test_views_exist_for_types_that_never_occurred(tmp_path: Path) -> None:
    with EventLog.open(tmp_path / "log", "only", wall_clock=lambda: 0, store=STORE) as log:
        log.append("search_failed", {"reason": "x"}, time_ns=0)
    lake = Lake(tmp_path / "lake", store=STORE)
    compact_log(tmp_path / "log", lake, robot="r")
    con = connect(lake)
    assert con.execute("SELECT count(*) FROM detection").fetchone() == (0,)
    columns = {c[0]: c[1] for c in con.execute("DESCRIBE detection").fetchall()}
    assert columns["support"].startswith("STRUCT(") and columns["run"] == "VARCHAR"
    assert con.execute("SELECT count(*) FROM events").fetchone() == (1,)


def test_tables_are_written_by_seq_with_the_derived_tables_beside_them(tmp_path: Path) -> None:
    lake = Lake(tmp_path / "lake", store=STORE)
    tables = events_to_tables(read_log(V1_LOG, store=STORE), STORE)
    shuffled = {t: table.take(list(range(table.num_rows))[::-1]) for t, table in tables.items()}
    info = lake.commit_tables(shuffled, robot="sim", run="rev", date="2024-01-01")
    stored = pq.ParquetFile(info.path / "detection.parquet")
    seqs = stored.read(columns=["seq"]).column("seq").to_pylist()
    assert seqs == sorted(seqs) and len(seqs) == tables["detection"].num_rows
    assert stored.metadata.num_row_groups == -(-len(seqs) // ROW_GROUP_ROWS)
    assert info.missing_derived() == []
    assert sorted(p.name for p in (info.path / DERIVED_DIR).iterdir()) == sorted(
        d.file_name for d in derived_tables(STORE)
    )
    # Derived files are not event types and not events.
    assert lake.event_types() == sorted(tables)
    assert len(lake.read_events(info)) == sum(t.num_rows for t in tables.values())


def test_a_log_being_written_is_not_compacted(tmp_path: Path) -> None:
    log = small_log(tmp_path / "log")
    with EventLog.open(log, "run-a", store=STORE), pytest.raises(LakeError, match="being written"):
        compact_log(log, Lake(tmp_path / "lake", store=STORE), robot="r")


def test_a_failed_commit_leaves_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from objsearch.events import lake as lake_module

    real = lake_module._write_parquet
    calls = []

    def failing(path: Path, table: pa.Table) -> None:
        calls.append(path)
        if len(calls) == 3:
            raise OSError(28, "No space left on device")
        real(path, table)

    monkeypatch.setattr(lake_module, "_write_parquet", failing)
    lake = Lake(tmp_path / "lake", store=STORE)
    with pytest.raises(OSError, match="No space"):
        compact_log(small_log(tmp_path / "log"), lake, robot="r")
    assert lake.runs() == []
    assert not list((tmp_path / "lake").glob("robot=*/date=*/run=*"))
    assert not list((tmp_path / "lake" / ".staging").iterdir())


def test_a_truncated_or_empty_file_is_named_and_its_run_left_out(tmp_path: Path) -> None:
    lake = Lake(tmp_path / "lake", store=STORE)
    good = compact_log(small_log(tmp_path / "a"), lake, robot="r", run="a")
    truncated = compact_log(small_log(tmp_path / "b", stream="b"), lake, robot="r", run="b")
    empty = compact_log(small_log(tmp_path / "c", stream="c"), lake, robot="r", run="c")
    path = truncated.path / "detection.parquet"
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    derived_tables(STORE)[0].path(empty.path).write_bytes(b"")
    runs, damaged = lake.scan()
    assert runs == [good]
    assert [(d.path, d.reason) for d in damaged] == [
        (
            truncated.path,
            "detection.parquet is truncated or not Parquet ("
            + str(path.stat().st_size)
            + " bytes, no PAR1 at both ends)",
        ),
        (empty.path, f"{derived_tables(STORE)[0].file_name} is empty"),
    ]
    with pytest.raises(LakeError, match=r"detection.parquet: damaged Parquet file"):
        lake.read_events(truncated)


def test_duckdb_reads_the_files_without_objsearch(tmp_path: Path) -> None:
    info = compact_log(V1_LOG, Lake(tmp_path, store=STORE), robot="sim")
    rows = (
        duckdb.connect()
        .execute(f"SELECT count(*), sum(support.at::INT) FROM '{info.path}/detection.parquet'")
        .fetchone()
    )
    raw = [e for e in read_log(V1_LOG, upcast=False, store=STORE) if e.type == "detection"]
    assert rows == (len(raw), sum(e.payload["at_static"] for e in raw))
