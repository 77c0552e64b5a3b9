"""The run digest (version 2) hashes values: equal values give one digest whatever buffers,
bitmaps, slices or chunks hold them; any changed value gives another."""

from __future__ import annotations

import io
import itertools
import math
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from objsearch.events.lake.digests import ipc_digest
from objsearch.events.lake.run_digest import (
    DIGEST_PREFIX,
    RunDigest,
    digest_version,
    values_digest,
)

CLOCK = pa.struct([("weekday", pa.int64()), ("minute", pa.int64())])
SUPPORT = pa.struct([("static_id", pa.string()), ("at", pa.bool_())])
SCHEMA = pa.schema(
    [
        ("seq", pa.int64()),
        ("task_id", pa.string()),
        ("clock", CLOCK),
        ("position", pa.list_(pa.float64())),
        ("support", SUPPORT),
        ("items", pa.list_(pa.struct([("name", pa.string()), ("xyz", pa.list_(pa.float64()))]))),
    ],
    metadata={"event_type": "t"},
)
ROWS: list[dict[str, Any]] = [
    {
        "seq": 1,
        "task_id": "a",
        "clock": None,
        "position": [1.0, 2.0],
        "support": {"static_id": "Table|1", "at": True},
        "items": [{"name": "x", "xyz": [0.5]}, {"name": "yz", "xyz": None}],
    },
    {
        "seq": 2,
        "task_id": None,
        "clock": {"weekday": 3, "minute": 450},
        "position": None,
        "support": None,
        "items": [],
    },
    {
        "seq": 3,
        "task_id": "bc",
        "clock": {"weekday": 0, "minute": 0},
        "position": [],
        "support": {"static_id": None, "at": False},
        "items": None,
    },
]


def _table(rows: list[dict[str, Any]] = ROWS) -> pa.Table:
    return pa.Table.from_pylist(rows, schema=SCHEMA)


def _parquet_round_trip(table: pa.Table) -> pa.Table:
    sink = io.BytesIO()
    pq.write_table(table, sink)
    return pq.read_table(io.BytesIO(sink.getvalue())).cast(SCHEMA)


def test_a_null_struct_read_back_from_parquet_has_the_digest_of_its_values() -> None:
    built = _table()
    read = _parquet_round_trip(built)
    assert read.equals(built)
    # The bug the version-2 digest fixes: the IPC bytes of the two differ (the null clock's
    # children carry validity bitmaps after Parquet), so version 1 refused the run.
    assert ipc_digest({"t": read}) != ipc_digest({"t": built})
    assert values_digest({"t": read}) == values_digest({"t": built})
    assert digest_version(values_digest({"t": built})) == 2
    assert values_digest({"t": built}).startswith(DIGEST_PREFIX)


def test_what_a_null_struct_holds_beneath_it_is_no_value() -> None:
    weekday = pa.array([7, 3, 0], pa.int64())  # 7 under the null row: garbage, not a value
    minute = pa.array([None, 450, 0], pa.int64())  # a bitmap where the other has none
    clock = pa.StructArray.from_arrays(
        [weekday, minute], fields=list(CLOCK), mask=pa.array([True, False, False])
    )
    built = _table()
    other = built.set_column(2, SCHEMA.field("clock"), clock)
    assert other.to_pylist() == built.to_pylist()
    assert values_digest({"t": other}) == values_digest({"t": built})


@pytest.mark.parametrize("cuts", [(), (1,), (2,), (1, 2)])
def test_chunks_and_slices_do_not_change_the_digest(cuts: tuple[int, ...]) -> None:
    whole = _table()
    bounds = [0, *cuts, whole.num_rows]
    pieces = [whole.slice(a, b - a) for a, b in itertools.pairwise(bounds)]
    assert values_digest({"t": pa.concat_tables(pieces)}) == values_digest({"t": whole})
    fed = RunDigest()
    for piece in pieces:
        fed.add("t", piece)
    assert fed.hexdigest() == values_digest({"t": whole})
    # a slice of a longer table (its buffers reach past the rows) hashes as its rows
    longer = pa.concat_tables([_table(ROWS[::-1]), whole]).combine_chunks()
    assert values_digest({"t": longer.slice(3)}) == values_digest({"t": whole})


def _changes() -> list[tuple[str, list[dict[str, Any]]]]:
    """Every way of changing one value of :data:`ROWS` that the digest must see."""
    out = []

    def changed(row: int, **fields: Any) -> list[dict[str, Any]]:
        rows = [dict(r) for r in ROWS]
        rows[row].update(fields)
        return rows

    out.append(("seq", changed(0, seq=9)))
    out.append(("task_id null", changed(0, task_id=None)))
    out.append(("task_id set", changed(1, task_id="a")))
    out.append(("clock set", changed(0, clock={"weekday": 0, "minute": 0})))
    out.append(("clock null", changed(1, clock=None)))
    out.append(("clock field", changed(1, clock={"weekday": 3, "minute": 451})))
    out.append(("list item", changed(0, position=[1.0, 2.5])))
    out.append(("list longer", changed(0, position=[1.0, 2.0, 0.0])))
    out.append(("list null", changed(2, position=None)))
    out.append(("list empty", changed(1, position=[])))
    out.append(("nested null", changed(0, support={"static_id": None, "at": True})))
    out.append(("struct null", changed(2, support=None)))
    out.append(("bool", changed(0, support={"static_id": "Table|1", "at": False})))
    out.append(("string bytes", changed(0, support={"static_id": "Table|2", "at": True})))
    out.append(
        (
            "string bounds",
            changed(0, items=[{"name": "xy", "xyz": [0.5]}, {"name": "z", "xyz": None}]),
        )
    )
    out.append(
        ("list bounds", changed(0, items=[{"name": "x", "xyz": []}, {"name": "yz", "xyz": [0.5]}]))
    )
    out.append(("-0.0", changed(0, position=[-0.0, 2.0])))
    out.append(("rows swapped", [ROWS[1], ROWS[0], ROWS[2]]))
    out.append(("row gone", ROWS[:2]))
    return out


@pytest.mark.parametrize(("what", "rows"), _changes(), ids=[w for w, _ in _changes()])
def test_any_changed_value_changes_the_digest(what: str, rows: list[dict[str, Any]]) -> None:
    assert values_digest({"t": _table(rows)}) != values_digest({"t": _table()}), what


def test_a_column_null_in_every_row_counts_as_no_column() -> None:
    """A type that gains a nullable field keeps its runs' digests (the rows read back with the
    new column null); a value set to null where it was its column's only one is still seen."""
    narrow = _table().drop_columns(["task_id"])
    nulls = _table().set_column(1, SCHEMA.field("task_id"), pa.nulls(3, pa.string()))
    assert values_digest({"t": nulls}) == values_digest({"t": narrow})
    only = [dict(r, task_id=None) for r in ROWS]
    only[0]["task_id"] = "a"
    assert values_digest({"t": _table(only)}) != values_digest({"t": nulls})


def test_nan_is_one_value_and_types_and_names_count() -> None:
    quiet = pa.array([math.nan], pa.float64())
    other_nan = pa.Array.from_buffers(
        pa.float64(), 1, [None, pa.py_buffer(bytes.fromhex("010000000000f87f"))]
    )
    assert values_digest({"t": pa.table({"x": quiet})}) == values_digest(
        {"t": pa.table({"x": other_nan})}
    )
    ints = pa.table({"x": pa.array([1], pa.int64())})
    assert values_digest({"t": ints}) != values_digest(
        {"t": ints.cast(pa.schema([("x", pa.float64())]))}
    )
    assert values_digest({"t": ints}) != values_digest({"t": ints.rename_columns(["y"])})
    assert values_digest({"t": ints}) != values_digest({"u": ints})
