"""The fleet lake (one Delta table, one transaction a run): commit, idempotency, replace,
removal, damage, many writers, plain readers. (Its answers equal the per-run-folder lake's after
``lake upgrade``: test_lake_folder_v1.py.)"""

from __future__ import annotations

import dataclasses
import logging
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import duckdb
import polars as pl
import pytest
from deltalake import DeltaTable

from objsearch.agent.catalogue import STORE
from objsearch.events import EventLog, _fs, read_log
from objsearch.events.arrow import events_to_tables
from objsearch.events.lake import TableLake, TableLakeError, add_log, is_table_lake
from objsearch.events.lake.schema import TABLE_DIR, run_parts, table_schema
from objsearch.events.lake.storage import file_sha256
from objsearch.events.lake.transactions import IDENTITY_INDEX_APP
from objsearch.events.sql_limits import close
from objsearch.replay.analytics import open_analytics, run_query, views_for

from .lake_logs import COMPACTING_WRITER, check_two_compactions_at_once, same_size_rewrite
from .payloads import EXAMPLES

V1_LOG = Path(__file__).parent / "fixtures" / "v1-log"
GOLDEN = Path(__file__).resolve().parents[1] / "replay" / "golden"


def small_log(directory: Path, *, stream: str = "run-a", n: int = 3) -> Path:
    with EventLog.open(
        directory, stream, wall_clock=lambda: 1_700_000_000_000_000_000, store=STORE
    ) as log:
        for i, (event_type, payload) in enumerate(EXAMPLES.items()):
            log.append(event_type, payload, time_ns=i, task_id="t1")
        for i in range(n):
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=100 + i)
    return directory


def one_type_log(directory: Path, *, stream: str, n: int) -> Path:
    """A log of ``n + 1`` events of one type (a commit of it is few files)."""
    with EventLog.open(
        directory, stream, wall_clock=lambda: 1_700_000_000_000_000_000, store=STORE
    ) as log:
        for i in range(n + 1):
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=i)
    return directory


def table_counts(lake: TableLake) -> list[tuple[str, str, int]]:
    con = open_analytics(lake.root)
    try:
        rows = run_query(con, "SELECT robot, run, count(*) FROM events GROUP BY ALL ORDER BY ALL")
        return [(str(r[0]), str(r[1]), int(r[2])) for r in rows[1]]
    finally:
        close(con)


def test_a_replace_is_one_version_and_removing_an_absent_run_says_so(tmp_path: Path) -> None:
    # The rest of replace and remove is the lake contract's (tests/events/contract/).
    lake = TableLake(tmp_path / "lake", store=STORE)
    add_log(small_log(tmp_path / "a", n=3), lake, robot="r", run="x")
    assert is_table_lake(tmp_path / "lake")
    before = DeltaTable(str(tmp_path / "lake" / TABLE_DIR)).version()
    add_log(small_log(tmp_path / "b", n=5), lake, robot="r", run="x", replace=True)
    assert DeltaTable(str(tmp_path / "lake" / TABLE_DIR)).version() == before + 1
    assert lake.remove_run("r", "x") and lake.runs() == []
    assert table_counts(lake) == []
    assert not lake.remove_run("r", "x")


def test_a_table_made_before_the_identity_index_still_refuses_the_same_log(
    tmp_path: Path,
) -> None:
    from deltalake import write_deltalake

    lake = TableLake(tmp_path / "lake", store=STORE)
    # as the first fleet lakes were made: no identity-index marker in the log
    write_deltalake(
        lake.uri, table_schema(STORE).empty_table(), partition_by=["type"], mode="ignore"
    )
    assert lake.table().transaction_version(IDENTITY_INDEX_APP) is None
    add_log(small_log(tmp_path / "log"), lake, robot="r", run="one")
    with pytest.raises(TableLakeError, match="already in the lake as run 'one'"):
        add_log(tmp_path / "log", lake, robot="r", run="two")


def test_a_query_gets_the_views_it_reads_and_those_they_read() -> None:
    definitions = {
        "detection": "",
        "task_started": "",
        "moved": "",
        "events": "",
        "detections": "SELECT * FROM detection d JOIN task_started s USING (task_id)",
        "scene_graph_at_seq": "WITH x AS (SELECT * FROM detections) SELECT * FROM x",
    }
    assert views_for("SELECT * FROM scene_graph_at_seq(3)", definitions) == {
        "scene_graph_at_seq",
        "detections",
        "detection",
        "task_started",
    }
    assert views_for('select count(*) from "Moved"', definitions) == {"moved"}
    assert views_for("SELECT 1", definitions) == set()
    # a look at the catalogue gets every view
    assert views_for("SELECT * FROM information_schema.tables", definitions) is None


def test_plain_duckdb_and_polars_read_the_table(tmp_path: Path) -> None:
    lake = TableLake(tmp_path / "lake", store=STORE)
    add_log(small_log(tmp_path / "log"), lake, robot="r2d2")
    table = str(tmp_path / "lake" / TABLE_DIR)
    frame = (
        pl.scan_delta(table)
        .filter(pl.col("type") == "search_failed")
        .select("run", "seq", pl.col("search_failed").struct.field("reason"))
        .sort("seq")
        .collect()
    )
    assert frame["reason"].to_list() == ["all candidates visited", "r0", "r1", "r2"]
    files = DeltaTable(table).file_uris(file_pruning_predicate=[("type", "=", "search_failed")])
    got = duckdb.execute(
        "SELECT search_failed.reason FROM read_parquet($files, union_by_name = true) ORDER BY seq",
        {"files": files},
    ).fetchall()
    assert [r[0] for r in got] == ["all candidates visited", "r0", "r1", "r2"]


def test_a_damaged_data_file_leaves_the_runs_other_types_in_the_views(tmp_path: Path) -> None:
    # That the file is left out, warned of and named by verify is the lake contract's; the
    # fleet lake leaves out the file alone, not its run (the folder lake leaves out the run).
    lake = TableLake(tmp_path / "lake", store=STORE)
    add_log(small_log(tmp_path / "log"), lake, robot="r2d2")
    victim = next(f for f in lake.data_files() if f.kind == "search_failed")
    path = tmp_path / "lake" / TABLE_DIR / victim.path
    path.write_bytes(path.read_bytes()[:-10])
    con = open_analytics(tmp_path / "lake")
    try:
        assert run_query(con, "SELECT count(*) FROM search_failed")[1] == [(0,)]
        assert run_query(con, "SELECT count(*) FROM task_ended")[1] == [(1,)]
    finally:
        close(con)


WRITER = """
import sys
from pathlib import Path
from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake, add_log
lake = TableLake(sys.argv[1], store=STORE)
for log in sys.argv[2:]:
    add_log(Path(log), lake, robot="r", run=Path(log).name)
"""


def test_concurrent_writers_lose_and_duplicate_nothing(tmp_path: Path) -> None:
    logs = [small_log(tmp_path / "logs" / f"log{i}", stream=f"s{i}", n=i) for i in range(4)]
    writers = 3
    # Every writer commits every log: the same runs race from all sides.
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", WRITER, str(tmp_path / "lake"), *map(str, logs[w:] + logs[:w])],
            env={**os.environ},
        )
        for w in range(writers)
    ]
    assert [p.wait(timeout=120) for p in procs] == [0] * writers
    sequential = TableLake(tmp_path / "seq", store=STORE)
    for log in logs:
        add_log(log, sequential, robot="r", run=log.name)
    concurrent = TableLake(tmp_path / "lake", store=STORE)
    assert [(r.run, r.digest) for r in concurrent.runs()] == [
        (r.run, r.digest) for r in sequential.runs()
    ]
    assert table_counts(concurrent) == table_counts(sequential)
    assert len(table_counts(concurrent)) == len(logs)


def test_a_failure_once_the_table_is_created_is_not_taken_for_a_lost_race(tmp_path: Path) -> None:
    # create() lets a writer that lost the race to create the table go on (delta-rs refuses its
    # version 0); it caught any exception then, so a failure after the table was written (here:
    # at the commit's durable step, through the kill tests' hook) vanished because the table
    # existed by then.
    lake = TableLake(tmp_path / "lake", store=STORE)

    def fail_once_created() -> None:
        if lake.exists():
            raise RuntimeError("after the commit")

    _fs.observe_durable_steps(fail_once_created)
    try:
        with pytest.raises(RuntimeError, match="after the commit"):
            lake.create()
    finally:
        _fs.observe_durable_steps(None)
    assert lake.exists()
    lake.create()  # and a second create of an existing table is still no error


@pytest.mark.slow  # three processes committing and compacting: 30-60 s on a shared machine
def test_writers_compacting_at_once_lose_and_duplicate_nothing(tmp_path: Path) -> None:
    # Each of 3 writers commits 3 runs of its own and compacts when the table holds more than
    # 8 files; before compactions claimed the table (TableLake._claim), two compactions
    # rewrote the same rows twice. Logs
    # of one event type: a commit is 5 files, so the compactions start after two commits and
    # each rewrites a few partitions (every type's made this test take 30-60 s under load).
    logs = [one_type_log(tmp_path / "logs" / f"log{i}", stream=f"s{i}", n=i) for i in range(9)]
    lake = TableLake(tmp_path / "lake", store=STORE)
    lake.create()
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", COMPACTING_WRITER, str(lake.root), *map(str, logs[w::3])]
        )
        for w in range(3)
    ]
    assert [p.wait(timeout=300) for p in procs] == [0] * 3
    sequential = TableLake(tmp_path / "seq", store=STORE)
    for log in logs:
        add_log(log, sequential, robot="r", run=log.name)
    assert [(r.run, r.digest) for r in lake.runs()] == [
        (r.run, r.digest) for r in sequential.runs()
    ]
    assert table_counts(lake) == table_counts(sequential)
    assert len(lake.data_files()) < 9 * len({f.kind for f in lake.data_files()})  # it compacted


def test_a_commit_whose_answer_was_lost_keeps_its_files(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The commit lands, but the writer hears a conflict (on S3: the answer to the conditional
    # put was lost and its retry found the version taken). It must find its own run there and
    # keep the files, not delete them as if another writer had won.
    from deltalake.exceptions import CommitFailedError

    real = DeltaTable.create_write_transaction
    heard: list[str] = []

    def lands_then_conflicts(self: DeltaTable, *args: object, **kwargs: object) -> None:
        real(self, *args, **kwargs)  # type: ignore[arg-type]
        if not heard:
            heard.append("conflict")
            raise CommitFailedError("Failed to commit transaction: Concurrent transaction failed.")

    monkeypatch.setattr(DeltaTable, "create_write_transaction", lands_then_conflicts)
    lake = TableLake(tmp_path / "lake", store=STORE)
    info = add_log(small_log(tmp_path / "log"), lake, robot="r")
    assert heard and lake.runs() == [info]
    assert lake.verify().damaged == []
    assert table_counts(lake) == [("r", "run-a", len(EXAMPLES) + 3)]


def test_compaction_keeps_every_row_and_bounds_the_files(tmp_path: Path) -> None:
    lake = TableLake(tmp_path / "lake", store=STORE)
    for i in range(3):
        add_log(small_log(tmp_path / f"log{i}", stream=f"s{i}", n=i), lake, robot="r")
    before = table_counts(lake)
    kinds = {f.kind for f in lake.data_files()}
    assert len(lake.data_files()) == 3 * len(kinds)  # one file a type a commit
    done = lake.compact(vacuum_hours=0)
    after = [f.kind for f in lake.data_files()]
    assert done["files_after"] == len(after) == len(set(after))  # at most one file a type
    assert set(after) <= kinds
    assert table_counts(lake) == before
    # The files the old versions read are gone from the folder, not only from the table.
    on_disk = sorted((tmp_path / "lake" / TABLE_DIR).glob("type=*/*.parquet"))
    assert len(on_disk) == len(after)


def test_files_of_a_writer_killed_before_its_commit_are_never_read(tmp_path: Path) -> None:
    lake = TableLake(tmp_path / "lake", store=STORE)
    add_log(small_log(tmp_path / "a", stream="a"), lake, robot="r")
    before = table_counts(lake)
    # What a writer killed between writing its files and committing leaves: files the log
    # does not name (the crash point itself is not simulated, only what it leaves).
    info = lake.runs()[0]
    orphan = dataclasses.replace(info, run="b", commit="dead")
    lake._write_files(
        {k: [t] for k, t in run_parts(lake.read_tables(info), orphan, STORE).items()}, "dead"
    )
    assert len(list((tmp_path / "lake" / TABLE_DIR).glob("type=*/part-dead*"))) > 0
    assert table_counts(lake) == before
    assert [r.run for r in lake.runs()] == ["a"]
    lake.compact(vacuum_hours=0)  # vacuum removes files no version names
    assert not list((tmp_path / "lake" / TABLE_DIR).glob("type=*/part-dead*"))


def test_a_streamed_commit_that_fails_leaves_no_file_it_wrote(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Files stored from memory, files spilled to their temporary name, and files closed before
    the failure: none is left behind (the next vacuum would delete them, but nothing waits)."""
    import objsearch.events.lake.stream_file as lt

    monkeypatch.setattr(lt, "SPILL_BYTES", 8192)
    monkeypatch.setattr(lt, "ROW_GROUP_ROWS", 50)
    close = lt._StreamFile.close
    closed: list[str] = []

    def failing_close(self: lt._StreamFile) -> object:
        if len(closed) == 3:
            raise OSError("disk full")
        closed.append(self.kind)
        return close(self)

    monkeypatch.setattr(lt._StreamFile, "close", failing_close)
    lake = TableLake(tmp_path / "lake", store=STORE)
    with pytest.raises(OSError, match="disk full"):
        add_log(GOLDEN / "sim-wpl-updates", lake, robot="sim")
    assert len(closed) == 3
    assert not list((tmp_path / "lake" / TABLE_DIR).rglob("*.parquet"))
    assert lake.runs() == []


def test_a_streamed_commit_equals_an_in_memory_one_whatever_the_chunks(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import objsearch.events.lake.commit as commit
    import objsearch.events.lake.digests as digests
    import objsearch.events.lake.stream_file as lt

    log = GOLDEN / "sim-wpl-updates"
    # Small digest slices (a format constant: both paths use it), then tiny chunks and row
    # groups for the streamed commit: every seam of the streaming path is crossed.
    monkeypatch.setattr(digests, "DIGEST_ROWS", 11)
    whole = TableLake(tmp_path / "whole", store=STORE)
    tables = events_to_tables(read_log(log, store=STORE), STORE)
    by_memory = whole.commit_tables(tables, robot="sim", run="robot", date="2026-01-01")
    for module in (commit, digests, lt):  # each reads its own binding of the chunk size
        monkeypatch.setattr(module, "CHUNK_EVENTS", 37)
    monkeypatch.setattr(lt, "ROW_GROUP_ROWS", 50)
    # Files past 8 KiB spill from memory to a temporary name, the others are stored from memory.
    monkeypatch.setattr(lt, "SPILL_BYTES", 8192)
    spilled: list[str] = []
    spill = lt._StreamFile._spill

    def counted_spill(self: lt._StreamFile) -> None:
        spilled.append(self.kind)
        spill(self)

    monkeypatch.setattr(lt._StreamFile, "_spill", counted_spill)
    # DuckDB's memory for the derived tables too small at first: it is given more until enough.
    monkeypatch.setattr(commit, "DERIVE_MEMORY", 1 << 16)
    spills: list[str] = []
    mkdtemp = tempfile.mkdtemp

    def counted(prefix: str) -> str:
        spills.append(prefix)
        return mkdtemp(prefix=prefix)

    monkeypatch.setattr(tempfile, "mkdtemp", counted)
    streamed = TableLake(tmp_path / "streamed", store=STORE)
    by_stream = add_log(log, streamed, robot="sim")
    assert len(spills) > 1  # the derived tables were tried again with more memory
    # both ways of storing a file were taken
    assert 0 < len(spilled) < len(streamed.data_files()), spilled
    stored = {str(p.relative_to(streamed.uri)) for p in Path(streamed.uri).rglob("*.parquet")}
    assert stored == {f.path for f in streamed.data_files()}  # no temporary name left
    assert (by_stream.digest, dict(by_stream.rows)) == (by_memory.digest, dict(by_memory.rows))
    got = streamed.read_tables(by_stream)
    for event_type, table in tables.items():
        assert got[event_type].equals(table), event_type
    queries = ["SELECT * FROM searches", "SELECT * FROM scene_graph", "SELECT * FROM eq4_updates"]
    answers = []
    for lake in (tmp_path / "whole", tmp_path / "streamed"):
        con = open_analytics(lake)
        try:
            answers.append([sorted(run_query(con, q)[1], key=repr) for q in queries])
        finally:
            close(con)
    assert answers[0] == answers[1] and answers[0][0]
    # The same log again is a no-op on both, and a migrated run keeps the same digest.
    assert add_log(log, whole, robot="sim") == by_memory
    assert add_log(log, streamed, robot="sim") == by_stream


def test_a_writer_killed_mid_commit_leaves_whole_runs_and_the_next_one_finishes(
    tmp_path: Path,
) -> None:
    logs = [small_log(tmp_path / "logs" / f"log{i}", stream=f"s{i}", n=i) for i in range(8)]
    lake = TableLake(tmp_path / "lake", store=STORE)
    lake.create()
    writer = subprocess.Popen([sys.executable, "-c", WRITER, str(lake.root), *map(str, logs)])
    deadline = time.monotonic() + 120
    try:  # kill it once it has committed a few runs: it is then somewhere inside another
        while len(lake.runs()) < 2 and writer.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
    finally:
        writer.kill()
        writer.wait()
    committed = lake.runs()
    assert 2 <= len(committed) < len(logs)
    counts = {run: n for _, run, n in table_counts(lake)}
    assert counts == {r.run: r.events for r in committed}  # every visible run is whole
    rerun = subprocess.run([sys.executable, "-c", WRITER, str(lake.root), *map(str, logs)])
    assert rerun.returncode == 0
    assert [r.run for r in lake.runs()] == sorted(log.name for log in logs)
    assert len(table_counts(lake)) == len(logs)


def test_two_compactions_at_once_rewrite_every_row_once(tmp_path: Path) -> None:
    check_two_compactions_at_once(tmp_path / "lake", tmp_path / "logs")


def test_a_same_size_valid_parquet_rewrite_is_left_out_and_named_by_verify(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    # What the damage battery found silent before files were content-addressed: the size and
    # the PAR1 ends are the same, the file decodes, its rows count as the log says.
    lake = TableLake(tmp_path / "lake", store=STORE)
    add_log(small_log(tmp_path / "log"), lake, robot="r2d2")
    victim = next(f for f in lake.data_files() if f.kind == "search_failed")
    same_size_rewrite(tmp_path / "lake" / TABLE_DIR / victim.path)
    with caplog.at_level(logging.WARNING):
        con = open_analytics(tmp_path / "lake")
    try:
        assert run_query(con, "SELECT count(*) FROM search_failed")[1] == [(0,)]
        assert run_query(con, "SELECT count(*) FROM task_ended")[1] == [(1,)]
    finally:
        close(con)
    assert "damaged data file left out of every view" in caplog.text
    assert victim.path in caplog.text and "not the ones written" in caplog.text
    [(name, why)] = lake.verify().damaged
    assert name == victim.path and "not the ones written" in why


def test_compacted_files_are_content_addressed_and_checked(tmp_path: Path) -> None:
    lake = TableLake(tmp_path / "lake", store=STORE)
    for i in range(3):
        add_log(small_log(tmp_path / f"log{i}", stream=f"s{i}", n=i), lake, robot="r")
    before = table_counts(lake)
    digests = {r.run: r.digest for r in lake.runs()}
    lake.compact(vacuum_hours=0)
    files = lake.data_files()
    assert all(file_sha256(f.path) is not None for f in files)
    assert lake.verify().damaged == []
    # reads and digests as before compaction
    assert table_counts(lake) == before
    for run in lake.runs():
        assert len(lake.read_events(run)) == run.events and digests[run.run] == run.digest
    victim = next(f for f in files if f.kind == "search_failed")
    same_size_rewrite(tmp_path / "lake" / TABLE_DIR / victim.path)
    _, bad = TableLake(lake.root, store=STORE).scan()
    assert [f.path for f, _ in bad] == [victim.path]


def test_unhashed_files_get_the_cheap_checks_until_compaction_hashes_them(
    tmp_path: Path,
) -> None:
    # Files delta-rs wrote with its own names (no hash), as the compaction of code before
    # content-addressed names did: every file of such a lake is unhashed.
    lake = TableLake(tmp_path / "lake", store=STORE)
    add_log(small_log(tmp_path / "a", n=3), lake, robot="r", run="w")
    add_log(small_log(tmp_path / "b", n=5), lake, robot="r", run="x")
    lake.table().optimize.compact()
    unhashed = [f for f in lake.data_files() if file_sha256(f.path) is None]
    assert unhashed
    victim = unhashed[0]
    path = tmp_path / "lake" / TABLE_DIR / victim.path
    intact = path.read_bytes()
    path.write_bytes(intact[:-1] + b"X")  # the same size, no PAR1 at the end
    _, bad = TableLake(lake.root, store=STORE).scan()
    assert [(f.path, "PAR1" in why) for f, why in bad] == [(victim.path, True)]
    path.write_bytes(intact)
    lake.compact(vacuum_hours=0)
    assert all(file_sha256(f.path) is not None for f in lake.data_files())
    assert [r.events for r in lake.runs()] == [len(EXAMPLES) + 3, len(EXAMPLES) + 5]
    assert [len(lake.read_events(r)) for r in lake.runs()] == [len(EXAMPLES) + 3, len(EXAMPLES) + 5]
    assert lake.verify().damaged == []


def test_a_replace_committed_while_a_compaction_plans_is_not_undone(tmp_path: Path) -> None:
    # Our compaction removes its input files in an append (create_write_transaction with
    # remove actions): a replace that removed one of them first must make it plan again, or
    # the run's old rows would come back beside the new ones.
    from .lake_logs import two_type_log

    lake = TableLake(tmp_path / "lake", store=STORE)
    for i in range(2):
        add_log(two_type_log(tmp_path / f"log{i}", stream=f"s{i}"), lake, robot="r", run=f"run{i}")
    real = TableLake._optimize
    raced: list[int] = []

    def replaced_meanwhile(self: TableLake, table: object) -> None:
        if not raced:
            raced.append(1)
            other = TableLake(self.root, store=STORE)
            add_log(
                small_log(tmp_path / "new", stream="new"),
                other,
                robot="r",
                run="run0",
                replace=True,
            )
        real(self, table)

    TableLake._optimize = replaced_meanwhile  # type: ignore[method-assign,assignment]
    try:
        lake.compact(vacuum_hours=None)
    finally:
        TableLake._optimize = real  # type: ignore[method-assign]
    assert raced
    assert [(r.run, r.events) for r in lake.runs()] == [("run0", len(EXAMPLES) + 3), ("run1", 4)]
    assert table_counts(lake) == [("r", "run0", len(EXAMPLES) + 3), ("r", "run1", 4)]
    assert all(file_sha256(f.path) is not None for f in lake.data_files())


def test_compaction_leaves_a_damaged_file_as_it_is(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    # Rewritten into a compacted file, a damaged file's rows would get a new, valid hash: the
    # damage hidden for good. Compaction leaves it; queries keep leaving it out.
    lake = TableLake(tmp_path / "lake", store=STORE)
    for i in range(3):
        add_log(small_log(tmp_path / f"log{i}", stream=f"s{i}", n=i), lake, robot="r")
    victim = next(f for f in lake.data_files() if f.kind == "search_failed")
    same_size_rewrite(tmp_path / "lake" / TABLE_DIR / victim.path)
    with caplog.at_level(logging.WARNING):
        lake.compact(vacuum_hours=0)
    assert "compaction leaves a damaged data file as it is" in caplog.text
    failed = [f for f in lake.data_files() if f.kind == "search_failed"]
    assert victim.path in {f.path for f in failed} and len(failed) == 2  # it, and the rest
    assert [name for name, _ in lake.verify().damaged] == [victim.path]
    _, bad = TableLake(lake.root, store=STORE).scan()
    assert [f.path for f, _ in bad] == [victim.path]


def test_a_replace_and_a_removal_rewrite_shared_files_content_addressed(tmp_path: Path) -> None:
    # Once compacted, a file holds the rows of many runs: replacing or removing one rewrites
    # its files with the other runs' rows kept, in their order, and every file keeps a hash.
    lake = TableLake(tmp_path / "lake", store=STORE)
    for i in range(3):
        add_log(small_log(tmp_path / f"log{i}", stream=f"s{i}", n=i), lake, robot="r", run=f"x{i}")
    lake.compact(vacuum_hours=None)
    before = {r.run: r for r in lake.runs()}
    add_log(small_log(tmp_path / "new", stream="new", n=7), lake, robot="r", run="x1", replace=True)
    assert all(file_sha256(f.path) is not None for f in lake.data_files())
    runs = {r.run: r for r in lake.runs()}
    assert runs["x0"] == before["x0"] and runs["x2"] == before["x2"]
    assert runs["x1"].events == len(EXAMPLES) + 7
    for run in runs.values():  # rows and digests read back as committed
        assert len(lake.read_events(run)) == run.events
    assert lake.remove_run("r", "x0")
    assert [r.run for r in lake.runs()] == ["x1", "x2"]
    assert all(file_sha256(f.path) is not None for f in lake.data_files())
    assert table_counts(lake) == [("r", "x1", len(EXAMPLES) + 7), ("r", "x2", len(EXAMPLES) + 2)]
    assert lake.verify().damaged == []


def test_a_replace_refuses_to_rewrite_a_damaged_file(tmp_path: Path) -> None:
    # The file holding the run also holds other runs' rows: rewritten, its damage would get a
    # fresh hash. The replace is refused, naming the file; the lake is as it was.
    lake = TableLake(tmp_path / "lake", store=STORE)
    for i in range(2):
        add_log(small_log(tmp_path / f"log{i}", stream=f"s{i}", n=i), lake, robot="r", run=f"x{i}")
    lake.compact(vacuum_hours=None)
    victim = next(f for f in lake.data_files() if f.kind == "search_failed")
    same_size_rewrite(tmp_path / "lake" / TABLE_DIR / victim.path)
    version = lake.table().version()
    with pytest.raises(TableLakeError, match="damaged") as refused:
        add_log(
            small_log(tmp_path / "new", stream="new", n=7), lake, robot="r", run="x1", replace=True
        )
    assert victim.path in str(refused.value)
    assert lake.table().version() == version


def test_a_compaction_committed_while_a_replace_plans_makes_it_plan_again(tmp_path: Path) -> None:
    # The other order of the race above: the replace read the table at the compaction's claim,
    # the compaction commits, then the replace removes files already removed. Without the
    # application transaction both carry (REWRITE_APP), delta-rs let it commit and the run's
    # old rows, rewritten by the compaction, were there beside the new ones.
    from .lake_logs import two_type_log

    lake = TableLake(tmp_path / "lake", store=STORE)
    for i in range(3):
        add_log(two_type_log(tmp_path / f"log{i}", stream=f"s{i}"), lake, robot="r", run=f"run{i}")
    real = TableLake._files_holding
    raced: list[int] = []

    def compacted_meanwhile(
        self: TableLake, table: DeltaTable, robot: str, runs: list[str]
    ) -> list[object]:
        if not raced:
            other = TableLake(self.root, store=STORE)
            pinned = other._claim()
            assert pinned is not None
            table.update_incremental()  # the replace decides from the claim's version
            raced.append(table.version())
            other._optimize(pinned)  # and the compaction commits first
        return real(self, table, robot, runs)  # type: ignore[return-value]

    TableLake._files_holding = compacted_meanwhile  # type: ignore[assignment,method-assign]
    try:
        add_log(
            small_log(tmp_path / "new", stream="new"), lake, robot="r", run="run0", replace=True
        )
    finally:
        TableLake._files_holding = real  # type: ignore[method-assign]
    assert raced
    assert [(r.run, r.events) for r in lake.runs()] == [
        ("run0", len(EXAMPLES) + 3),
        ("run1", 4),
        ("run2", 4),
    ]
    assert table_counts(lake) == [
        ("r", "run0", len(EXAMPLES) + 3),
        ("r", "run1", 4),
        ("r", "run2", 4),
    ]
