"""One session recorded twice at once by Debian's ROS 1 tools (fixtures/twice/README.md): a full
``rosbag record`` and a split one, each receiving every message at its own moment. The lake
keeps every derived row once, judged by what was recorded (header stamp and content), not by
when each recorder heard it."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake
from objsearch.pipeline.bags.ingest import ingest

FIXTURES = Path(__file__).parent / "fixtures" / "twice"
FULL = FIXTURES / "full.bag"
PIECES = sorted((FIXTURES / "split").glob("piece_*.bag"))
DERIVED = ("pose_observed", "objects_detected")


def _run(lake: Path) -> dict[str, pa.Table]:
    [run] = TableLake(lake, store=STORE).runs()
    return dict(TableLake(lake, store=STORE).read_tables(run))


def _recorded(table: pa.Table) -> list[tuple[object, ...]]:
    """A derived table's rows without their ids and receive times, sorted."""
    keep = [c for c in table.column_names if c not in ("event_id", "seq", "recorded_at_ns")]
    return sorted(tuple(map(str, row.values())) for row in table.select(keep).to_pylist())


@pytest.fixture(scope="module")
def full_alone(tmp_path_factory: pytest.TempPathFactory) -> dict[str, pa.Table]:
    lake = tmp_path_factory.mktemp("full") / "lake"
    [result] = ingest([FULL], lake)
    assert result.error is None
    return _run(lake)


def test_the_fixture_is_what_the_readme_says(full_alone: dict[str, pa.Table]) -> None:
    assert len(PIECES) == 9
    assert full_alone["pose_observed"].num_rows == 151
    assert full_alone["objects_detected"].num_rows == 16


@pytest.mark.parametrize(
    "order",
    [
        "full first",
        "pieces first",
        "pieces backwards, then full",
        "an odometry-only piece first",
    ],
)
def test_derived_rows_of_a_session_recorded_twice_are_kept_once(
    order: str, full_alone: dict[str, pa.Table], tmp_path: Path
) -> None:
    bags = {
        "full first": [FULL, *PIECES],
        "pieces first": [*PIECES, FULL],
        "pieces backwards, then full": [*reversed(PIECES), FULL],
        "an odometry-only piece first": [PIECES[4], FULL, *PIECES[:4], *PIECES[5:]],
    }[order]
    results = ingest(bags, tmp_path / "lake")
    assert [r.error for r in results] == [None] * len(bags)
    tables = _run(tmp_path / "lake")
    for event_type in DERIVED:
        # Each message once, at its header stamp: the full recording's rows, nothing more.
        assert _recorded(tables[event_type]) == _recorded(full_alone[event_type]), event_type
    ids = [i for t in tables.values() for i in t["event_id"].to_pylist()]
    assert len(ids) == len(set(ids))
    agent = [
        i
        for t in tables.values()
        for i, s in zip(t["event_id"].to_pylist(), t["stream"].to_pylist(), strict=True)
        if not s.startswith("bag:")
    ]
    assert len(agent) == 28


def test_the_run_is_the_same_whatever_order_the_recordings_came_in(tmp_path: Path) -> None:
    """Up to recorded_at_ns, which is when the recording ingested first received each message
    (a bag whose every row the run holds already adds nothing)."""
    ingest([FULL, *PIECES], tmp_path / "a")
    ingest([*reversed(PIECES), FULL], tmp_path / "b")
    a, b = _run(tmp_path / "a"), _run(tmp_path / "b")
    assert a.keys() == b.keys()
    for event_type in a:
        x, y = (
            t.sort_by("seq").drop_columns(["recorded_at_ns"])
            for t in (a[event_type], b[event_type])
        )
        assert x.equals(y), event_type
