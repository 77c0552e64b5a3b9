"""Small event logs the lake tests commit (shared helpers, not tests)."""

from __future__ import annotations

from pathlib import Path

from objsearch.agent.catalogue import STORE
from objsearch.events import EventLog

from .payloads import EXAMPLES, OLD_EXAMPLES

#: A log written by format-1 code (old event versions, plain CRCs).
V1_LOG = Path(__file__).parent / "fixtures" / "v1-log"


def small_log(directory: Path, *, stream: str = "run-a", n: int = 3) -> Path:
    """Every event type once, an old detection version, then ``n`` failures."""
    with EventLog.open(
        directory, stream, wall_clock=lambda: 1_700_000_000_000_000_000, store=STORE
    ) as log:
        for i, (event_type, payload) in enumerate(EXAMPLES.items()):
            log.append(event_type, payload, time_ns=i, task_id="t1")
        log.append("detection", OLD_EXAMPLES["detection", 1], time_ns=99, version=1)
        for i in range(n):
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=100 + i)
    return directory


def two_type_log(directory: Path, *, stream: str = "run-a") -> Path:
    """Two event types: every kind of step of a commit, few files (each kill costs a commit)."""
    with EventLog.open(
        directory, stream, wall_clock=lambda: 1_700_000_000_000_000_000, store=STORE
    ) as log:
        log.append("task_started", EXAMPLES["task_started"], time_ns=1, task_id="t1")
        for i in range(3):
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=100 + i)
    return directory


def check_two_compactions_at_once(root: str | Path, logs: Path) -> None:
    """Two compactions of the fleet lake at ``root`` overlap: while one has planned from the
    table (claimed, pinned at its version), another compacts it whole and commits. The first
    must not commit its plan (delta-rs would let it: both remove the same files and every row
    would be there twice); it plans again and the lake holds what a sequential run holds."""
    import pyarrow.compute as pc

    from objsearch.events.lake import TableLake, add_log

    lake = TableLake(root, store=STORE)
    for i in range(3):
        add_log(two_type_log(logs / f"log{i}"), lake, robot="r", run=f"run{i}")
    before = sorted((r.run, r.digest, r.events) for r in lake.runs())
    rows = lake.files_dataset(lake.data_files()).to_table().num_rows
    overlapped: list[int] = []
    real = TableLake._optimize

    def planned_then_overtaken(self: TableLake, table: object) -> None:
        if not overlapped:
            overlapped.append(table.version())  # type: ignore[attr-defined]
            TableLake(self.root, store=STORE).compact(vacuum_hours=None)  # commits first
        real(self, table)

    TableLake._optimize = planned_then_overtaken  # type: ignore[method-assign,assignment]
    try:
        lake.compact(vacuum_hours=None)
    finally:
        TableLake._optimize = real  # type: ignore[method-assign]
    assert overlapped
    assert sorted((r.run, r.digest, r.events) for r in lake.runs()) == before
    files = lake.data_files()
    table = lake.files_dataset(files).to_table()
    assert table.num_rows == rows  # nothing lost, nothing twice
    kind = pc.field("type")
    events = table.filter((kind != "_run") & ~pc.starts_with(kind, "derived."))
    keys = events.group_by(["run", "event_id"]).aggregate([]).num_rows
    assert keys == events.num_rows == 3 * 4  # every event of the three runs, once
    assert len(files) == len({f.kind for f in files})  # compacted: one file a type


#: A writer process (``python -c``): commits the logs named after the lake, compacting every
#: few commits, whatever another writer claimed.
COMPACTING_WRITER = """
import sys
from pathlib import Path
import objsearch.events.lake.rewrite as lr
from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake, add_log
lr.COMPACT_AT_FILES = 8  # every few commits: the writers' compactions overlap
lr.COMPACTION_CLAIM_FRESH_S = 0.0  # and none leaves it to another
lake = TableLake(sys.argv[1], store=STORE)
for log in sys.argv[2:]:
    add_log(Path(log), lake, robot="r", run=Path(log).name)
"""


def same_size_rewrite(path: Path) -> None:
    """Rewrite the Parquet file at ``path`` as valid Parquet of the same size with one value
    changed: its first non-null ``seq`` one more (zstd, page checksums and all), brought to the
    old size by leaving out some columns' statistics, a key of the schema's metadata and the
    zstd level — damage that the size and the ``PAR1`` ends do not show."""
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    size = path.stat().st_size
    table = pq.read_table(path)
    seq = table.column("seq").combine_chunks()
    values = seq.to_pylist()
    row = next(i for i, v in enumerate(values) if v is not None)
    values[row] += 1
    table = table.set_column(table.schema.get_field_index("seq"), "seq", pa.array(values, seq.type))
    assert not pc.all(pc.equal(table.column("seq"), seq)).as_py()
    columns = [c for c in pq.ParquetFile(path).schema.names]
    # fewer columns' statistics to make it smaller, then a pad and the level to make it fit
    for drop in range(len(columns) + 1):
        for level in (None, *range(1, 20)):
            for pad in range(256):  # the file grows with the pad: stop once past the size
                padded = table.replace_schema_metadata({"pad": "x" * pad}) if pad else table
                pq.write_table(
                    padded,
                    path,
                    compression="zstd",
                    compression_level=level,
                    write_page_checksum=True,
                    write_statistics=columns[drop:] or False,
                )
                grown = path.stat().st_size
                if grown == size:
                    return
                if grown > size:
                    break
    raise AssertionError(f"{path}: could not rewrite it at {size} bytes")
