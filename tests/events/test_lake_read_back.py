"""A run read back from the fleet lake: the run's digest (``events/lake/run_digest.py``) hashes the
rows' values, so a run whose rows read back from Parquet with other buffers than the rows built
from its events (a null struct: ``task_started.clock``) is not refused as damaged, while any
changed value still is; runs committed under the old digest (``sha256:``, Arrow IPC bytes) still
verify. ``replay``, ``where`` and ``audit`` answer from a lake run as from its log."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from objsearch.agent.catalogue import STORE
from objsearch.cli import main
from objsearch.events import InvalidEventError, read_log
from objsearch.events.arrow import tables_to_events
from objsearch.events.lake import TableLake, TableLakeError, add_log
from objsearch.events.lake.digests import table_digest
from objsearch.events.lake.run_digest import DIGEST_PREFIX
from objsearch.events.lake.run_read import RunReader

from .lake_logs import two_type_log


@pytest.fixture(scope="module")
def search_lake(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A real search's log (it records no clock: ``task_started.clock`` is null) and a lake
    holding it as run ``r/robot``, both made by the CLI."""
    root = tmp_path_factory.mktemp("search-lake")
    log, lake = root / "L", root / "K"
    search = ["search", "Cup", "--start", "kitchen-1", "--log", str(log), "--format", "json"]
    assert main(search) == 0
    assert main(["lake", "add", str(log), "--robot", "r", "--lake", str(lake)]) == 0
    return log, lake


def _answer(capsys: pytest.CaptureFixture[str], argv: list[str]) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("command", [["replay"], ["where", "Cup"]])
def test_a_search_run_answers_from_the_lake_as_from_its_log(
    search_lake: tuple[Path, Path], command: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    log, lake = search_lake
    from_log = _answer(capsys, [*command, str(log), "--no-progress"])
    from_lake = _answer(capsys, [*command, str(lake), "--run", "robot", "--no-progress"])
    assert from_lake[0] == from_log[0] and from_lake[0] in (0, 1), from_lake[2]
    assert from_lake[1] == from_log[1]
    assert "damaged" not in from_lake[2]


def test_a_search_run_audits_from_the_lake_as_from_its_log(
    search_lake: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log, lake = search_lake
    argv = ["audit", "--format", "json", "--plots", "none", "--no-progress"]
    from_log = _answer(capsys, [*argv, str(log), "--out", str(tmp_path / "a")])
    from_lake = _answer(capsys, [*argv, str(lake), "--run", "robot", "--out", str(tmp_path / "b")])
    assert from_lake[0] == from_log[0] == 0, from_lake[2]
    assert json.loads(from_lake[1]) == json.loads(from_log[1])


def test_the_lake_run_reads_back_as_its_log_and_its_digest_is_of_values(
    search_lake: tuple[Path, Path],
) -> None:
    log, root = search_lake
    lake = TableLake(root, store=STORE)
    (run,) = lake.runs()
    assert run.digest.startswith(DIGEST_PREFIX)
    assert lake.read_events(run) == list(read_log(log, store=STORE))
    tables = lake.read_tables(run)
    assert table_digest(tables) == run.digest
    # the null clock: a null struct whose children carry validity bitmaps after Parquet, none
    # when built from the events; the values are equal, and so is the digest
    clock = tables["task_started"].column("clock")
    assert clock.null_count == clock.length() == 1


#: A fleet lake written by the code of 2cf7381, whose run digests are version 1 (Arrow IPC
#: bytes): a real search (null clock) as run r/cup, every example payload as r2d2/run-a
#: (tests/events/fixtures/README.md).
DIGEST_V1 = Path(__file__).parent / "fixtures" / "lake-digest-v1"


@pytest.fixture
def v1_lake(tmp_path: Path) -> Path:
    shutil.copytree(DIGEST_V1, tmp_path / "v1")
    return tmp_path / "v1"


def test_runs_committed_with_the_version_1_digest_still_verify(v1_lake: Path) -> None:
    lake = TableLake(v1_lake / "lake", store=STORE)
    runs = {r.run: r for r in lake.runs()}
    assert sorted(runs) == ["cup", "run-a"]
    assert all(r.digest.startswith("sha256:") for r in runs.values())
    for name, log in (("cup", "search-log"), ("run-a", "examples-log")):
        events = lake.read_events(runs[name])
        assert events == list(read_log(v1_lake / log, store=STORE)), name


def test_adding_a_version_1_run_again_is_a_no_op_and_other_content_is_refused(
    v1_lake: Path,
) -> None:
    lake = TableLake(v1_lake / "lake", store=STORE)
    before = {r.run: r for r in lake.runs()}
    stored = {
        (t, v)
        for t, part in lake.read_tables(before["cup"]).items()
        for v in part.column("version").to_pylist()
    }
    if all(v == STORE.registry.latest_version(t) for t, v in stored):
        again = add_log(v1_lake / "search-log", lake, robot="r", run="cup")
        assert again == before["cup"]
    else:  # a type gained a version since: the log's events upcast to other rows than stored
        with pytest.raises(TableLakeError, match="other content"):
            add_log(v1_lake / "search-log", lake, robot="r", run="cup")
    other = two_type_log(v1_lake / "other-log")
    with pytest.raises(TableLakeError, match="other content"):
        add_log(other, lake, robot="r", run="cup")


def _change_one_value(lake: TableLake, kind: str, column: str, field: str) -> None:
    """Rewrite the run's data file of ``kind`` as valid Parquet, under its name, with the first
    row's ``column.field`` changed."""
    (f,) = [d for d in lake.data_files() if d.kind == kind and "cup" in _runs_in(lake, d.path)]
    path = Path(lake.uri) / f.path
    table = pq.read_table(path)
    rows = table.to_pylist()
    rows[0][column][field] = f"{rows[0][column][field]}x"
    pq.write_table(pa.Table.from_pylist(rows, schema=table.schema), path)


def _runs_in(lake: TableLake, rel: str) -> set[str]:
    return set(pq.read_table(Path(lake.uri) / rel, columns=["run"]).column("run").to_pylist())


@pytest.mark.parametrize("version", [1, 2])
def test_a_changed_value_is_refused_under_either_digest(
    v1_lake: Path, tmp_path: Path, version: int
) -> None:
    if version == 1:
        lake = TableLake(v1_lake / "lake", store=STORE)
    else:
        lake = TableLake(tmp_path / "v2", store=STORE)
        add_log(v1_lake / "search-log", lake, robot="r", run="cup")
    (run,) = [r for r in lake.runs() if r.run == "cup"]
    assert len(lake.read_events(run)) == 188
    _change_one_value(lake, "task_started", "task_started", "target")
    with pytest.raises(TableLakeError, match="damaged"):
        lake.read_events(run)


def test_a_run_streamed_reads_as_read_whole_and_a_write_between_the_reads_is_refused(
    search_lake: tuple[Path, Path], tmp_path: Path
) -> None:
    log, root = search_lake
    copy = tmp_path / "K"
    shutil.copytree(root, copy)
    lake = TableLake(copy, store=STORE)
    (run,) = lake.runs()
    reader = RunReader(lake, run)
    assert list(reader.events()) == lake.read_events(run) == list(read_log(log, store=STORE))
    assert reader.streams["run_started"] == {"robot"}
    # the agent's stream alone, as replay and where read it
    assert list(RunReader(lake, run).events(["robot"])) == lake.read_events(run)
    assert list(RunReader(lake, run).events(["another"])) == []
    # checked, then a file of the run written to before the events are read: refused at the end
    reader = RunReader(lake, run)
    reader.check()
    (detections,) = [f for f in lake.data_files() if f.kind == "detection"]
    os.utime(Path(lake.uri) / detections.path, ns=(1, 1))
    with pytest.raises(TableLakeError, match="changed while it was read"):
        list(reader.events())


def test_rows_whose_envelope_breaks_the_rules_are_refused_as_events_are(
    search_lake: tuple[Path, Path],
) -> None:
    """Rows read back become events without a check each when their envelope columns keep the
    rules; a row that breaks one is checked as Event(...) checks it, and refused."""
    lake = TableLake(search_lake[1], store=STORE)
    (run,) = lake.runs()
    moved = lake.read_tables(run)["moved"]
    assert len(tables_to_events([moved], STORE)) == moved.num_rows
    for column, value in (("seq", 0), ("event_id", "not-a-uuid-but-36-characters-long-xx")):
        at = moved.schema.get_field_index(column)
        values = moved.column(at).to_pylist()
        values[-1] = value
        bad = moved.set_column(
            at, moved.schema.field(at), pa.array(values, moved.schema.field(at).type)
        )
        with pytest.raises(InvalidEventError):
            tables_to_events([bad], STORE)


def test_the_folds_of_a_streamed_event_share_one_decode(search_lake: tuple[Path, Path]) -> None:
    """Each event of a lake run carries its record on its payload (a ``ReadPayload``, as an event
    read from a log keeps the record a fold decodes), so every fold that decodes it (a ``where``
    folds each event into four projections) gets that one record, while the reader holds the
    event or after: one mechanism for logs and lakes, no decode shared through a context."""
    from objsearch.agent.catalogue import LATEST, decode
    from objsearch.events.envelope import ReadPayload

    _, root = search_lake
    lake = TableLake(root, store=STORE)
    (run,) = lake.runs()
    held = []
    for event in RunReader(lake, run).events():
        assert type(event.payload) is ReadPayload, event.type
        record = decode(event, LATEST[event.type])
        assert decode(event, LATEST[event.type]) is record, event.type
        held.append((event, record))
    assert len(held) == run.events
    for event, record in held:  # the reader moved on: the record is the payload's still
        assert decode(event, LATEST[event.type]) is record, event.type
    # What a fold decodes is what the log's event decodes to.
    logged = {e.seq: decode(e, LATEST[e.type]) for e in read_log(search_lake[0], store=STORE)}
    assert all(logged[event.seq] == record for event, record in held)
