"""The fleet lake: every run of every robot in one Delta Lake table (``objsearch.lake/2``), one
transaction a run. :func:`open_lake` opens one; the table's seams are modules of their own:

* :mod:`.common`: what the lake shares with its writers and readers (its error, names and
  dates, a table's conformance to its event type's schema, the cheap whole-file check);
* :mod:`.schema`: the table's columns and a run's rows in it; :mod:`.storage`: object-store
  settings, content-addressed file names, file statistics; :mod:`.transactions`: the Delta
  application transactions commits carry; :mod:`.head`: the record of the latest commit;
* :mod:`.table` (the table and its files), :mod:`.read` (runs, a run's rows, the files a query
  may read), :mod:`.checks` (the log against the runs' records), :mod:`.rewrite` (replace,
  remove, compaction), :mod:`.commit` (one transaction a run), :mod:`.verify` (every byte):
  the layers of :class:`~.fleet.TableLake`, each importing only those before it;
* :mod:`.add` (``lake add``: an agent's log as a run), :mod:`.run_read` (a run streamed),
  :mod:`.run_digest` / :mod:`.digests` (a run's digests), :mod:`.verified` (the verification
  cache), :mod:`.folder_v1` (the retired per-run-folder lake, read only by its migration).
"""

from .add import add_log
from .common import LakeError, parquet_problem
from .fleet import TableLake
from .open import NoLakeError, open_lake
from .schema import TABLE_FORMAT, DataFile, TableCheck, TableLakeError, TableRaceLost, TableRun
from .table import is_table_lake

__all__ = [
    "TABLE_FORMAT",
    "DataFile",
    "LakeError",
    "NoLakeError",
    "TableCheck",
    "TableLake",
    "TableLakeError",
    "TableRaceLost",
    "TableRun",
    "add_log",
    "is_table_lake",
    "open_lake",
    "parquet_problem",
]
