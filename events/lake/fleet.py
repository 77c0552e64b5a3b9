"""The fleet lake: every run in one Delta Lake table, one transaction per run.

Layout (a local folder, or ``s3://bucket/prefix``)::

    LAKE/events/_delta_log/…                 the table's transaction log (JSON + checkpoints)
    LAKE/events/type=<event type>/*.parquet  rows of that event type, every run
    LAKE/events/type=derived.<name>.v<N>/    a derived table's rows (per-run summaries)
    LAKE/events/type=_run/                   one row a run: what it holds (digest, rows, source)

One table, partitioned by ``type``; the run is a column (``robot``, ``date``, ``run``,
``commit``), so the number of files does not grow with the number of runs once the table is
compacted (:meth:`TableLake.compact`; ``lake add`` compacts when the table holds more than
:data:`.rewrite.COMPACT_AT_FILES` files). Each event type's payload is one struct column named after the
type (``detection.mask_area``); the envelope columns are shared. Because a run's events, its
derived tables and its ``_run`` row are added in **one Delta transaction**, a reader (or a
crash) sees all of a run or none of it, with no staging folder, rename or lock of ours:

* **commit**: an append carrying the Delta *application transaction* ``objsearch/<robot>/<run>``.
  Two writers committing the same run at once conflict on it (the table's optimistic
  concurrency); the loser re-reads and finds the run there — the same content is a no-op,
  other content needs ``replace``. Writers of different runs never conflict (blind appends);
  a commit that loses a race with another transaction is retried (:data:`.transactions.COMMIT_TRIES`).
* **replace** / **remove**: one transaction, bumping the run's application-transaction version,
  that removes every data file that may hold the run's rows (by the log's statistics) and adds
  their other rows, in their order, with the run's new rows after them (ours, not delta-rs's
  overwrite or delete: those name their files without a hash).
* **damage**: every data file this module writes is **content-addressed** — named after the
  SHA-256 of its bytes, ``type=<kind>/part-<token>-<sha256>.zstd.parquet`` (a file written from
  memory is hashed before it is stored; a streamed one is hashed as it is written under a
  temporary name in the partition's folder, then renamed — locally a rename and an fsync of the
  folder, on S3 a copy and a delete — before the commit names it), so any reader finds each
  file's hash in the table's log alone. Compaction is ours (:meth:`TableLake._optimize`) and
  writes content-addressed files too, after checking each input (a damaged one stays as it is:
  rewritten, its damage would get a fresh hash). Every query (:meth:`TableLake.scan`;
  ``replay`` and ``where`` check a run's digest instead) leaves out, naming it, a file that is
  missing, has another size than the log records, or — content-addressed — whose bytes do not
  hash to its name's SHA-256. A file is hashed once per change of its ``stat`` identity (size,
  mtime, ctime, inode), remembered in a verification cache outside the lake
  (:mod:`.verified`): a query costs one ``stat`` a file once this machine has hashed
  the files, and the first query after a file appears or changes hashes that file (about as
  long as reading it). Unhashed files (written by code before content-addressed names, or by
  delta-rs: its compaction, overwrite and delete name their files without a hash) get the cheap
  check only (no ``PAR1`` at both ends: cut); ``compact`` rewrites them content-addressed. On
  S3 a query hashes nothing (a first sight would download every object once per machine: see
  ``docs/analytics.md``). ``verify`` hashes every content-addressed file in full, whatever the
  cache says, decodes every file (page checksums on) and compares its rows with the log's.
* **the log against the runs' records**: each ``_run`` row records its run's rows per event
  type and derived table, and each commit records the version it made (:data:`.head.HEAD_FILE`), so
  ``query``, ``lake ls``, ``lake add`` and ``lake compact`` refuse a table whose log lost an
  ``add``, a whole commit or its newest commits (:meth:`TableLake.check_runs`), and ``verify``
  counts each run's rows; a damaged ``_run`` file costs its runs, not the lake
  (:meth:`TableLake.read_runs`).

Any Delta reader reads the table: DuckDB's ``delta_scan`` (the ``delta`` extension),
``polars.scan_delta``, ``deltalake.DeltaTable(…).to_pyarrow_dataset()``; ``docs/analytics.md``.
"""

from __future__ import annotations

from .commit import LakeCommits
from .verify import LakeVerify


class TableLake(LakeCommits, LakeVerify):
    """The fleet lake at ``root`` (a folder or an ``s3://`` URI), read and written with the
    store ``store`` (its event types, schemas, upcasters and derived tables). Cheap to create;
    :func:`~objsearch.events.lake.open_lake` is how a command opens one."""
