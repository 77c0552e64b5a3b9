"""The analysts' DuckDB: the lake's per-type views plus convenience views and the scene graph.

Convenience views (one row per …):

* ``searches`` — task: target, start, scene, method, update mode, success, path length, duration,
  rooms planned, detections, found instance, ``task_index`` (1, 2, … within the run).
* ``plans`` — ``plan_computed``: the task's target, room, ``room_rank`` within the task,
  ``chosen_order`` (static ids), ``first_choice``, candidates, WPL value.
* ``detections`` — ``detection``: the task's target, ``is_target``, position ``x, y, z``, the
  nearest static object (``static_id``, ``static_class``) and ``at_static``.
* ``scene_graph`` — (robot, run, dynamic, static): Rel at the end of each run.

* ``eq4_updates`` — (run, task end, dynamic class) where Eq. 4 updated the class.

``searches``, ``eq4_updates`` and ``scene_graph`` read the tables each run derived when it was
committed (:mod:`objsearch.events.derived`; the SQL of the Eq. 4 ones is the agent's,
:mod:`objsearch.agent.scene_graph_sql`); when no run has a derived table at its current version
(older code wrote them), the view is the same SQL over the events, live (see :func:`_open_fleet`).

Table macros ``scene_graph_at_seq(s)`` and ``scene_graph_at_time(t_ns)`` give Rel as it was right
after seq ``s`` (or the last event with ``time_ns <= t_ns``) of every run, computed with the closed
form of Eq. 4 instead of a fold: a pair's value after k updates of its dynamic class is

    Rel_k = Rel_0 / 2^k + Σ_j [o_d seen at o_s in update j] / 2^(k - j + 1),

i.e. each update halves everything before it and the update that saw o_d at o_s adds 1/2. Which
task ends count as updates of o_d follows :class:`objsearch.agent.scene_graph.SceneGraphProjection`
exactly (tested against the fold): ``eq4_updates`` holds them by the update mode of the latest
``run_started`` and the experience of the accepted detections since the task began, numbered
``n`` = 1, 2, … per class; the macro keeps those up to the cut-off and after the latest
``scene_graph_seeded`` before it (k = last n − last n before the seed; age = last n − n + 1) and
adds the seed's prior.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any, Final

import duckdb

from objsearch.agent.catalogue import STORE
from objsearch.agent.scene_graph_sql import LIMIT_SEQ, LIMIT_TIME, SCENE_GRAPH_BODY
from objsearch.events.derived import derived_tables
from objsearch.events.lake import TableLake, open_lake
from objsearch.events.lake import rewrite as lake_rewrite
from objsearch.events.lake.schema import derived_column, derived_kind
from objsearch.events.sql import (
    check_read_only,
    create_fleet_views,
    fleet_source,
    lock_down,
)
from objsearch.events.sql_limits import (
    DEFAULT_MEMORY_LIMIT,
    DEFAULT_THREADS,
    DEFAULT_TIMEOUT_S,
    BoundedResult,
    Deadline,
    apply_limits,
)
from objsearch.events.sql_quote import quote_ident

_log = logging.getLogger(__name__)

_PLANS: Final = """
CREATE OR REPLACE VIEW plans AS
SELECT p.robot, p.date, p.run, p.task_id, p.seq, p.time_ns, s.target, p.room,
       row_number() OVER (PARTITION BY p.robot, p.run, p.task_id ORDER BY p.seq) AS room_rank,
       p.objective, p.alpha, p."order" AS chosen_order, p."order"[1] AS first_choice,
       len(p.candidates) AS candidates, p.value AS wpl_value, p.terms, p.room_order
FROM plan_computed p
LEFT JOIN task_started s ON s.robot = p.robot AND s.run = p.run AND s.task_id = p.task_id
"""

_DETECTIONS: Final = """
CREATE OR REPLACE VIEW detections AS
SELECT d.robot, d.date, d.run, d.task_id, d.seq, d.time_ns, s.target,
       d.object_class, d.instance_id, d.mask_area, d.accepted,
       d.object_class = s.target AS is_target,
       d.position[1] AS x, d.position[2] AS y, d.position[3] AS z,
       d.support.static_id AS static_id, d.support.static_class AS static_class,
       coalesce(d.support."at", false) AS at_static
FROM detection d
LEFT JOIN task_started s ON s.robot = d.robot AND s.run = d.run AND s.task_id = d.task_id
"""


def _common_ddl() -> dict[str, str]:
    """``plans``, ``detections`` and the scene-graph macros, by name: over the views, whatever
    the lake."""
    return {
        "plans": _PLANS,
        "detections": _DETECTIONS,
        "scene_graph_at_seq": "CREATE OR REPLACE MACRO scene_graph_at_seq(upto_seq) AS TABLE "
        + SCENE_GRAPH_BODY.format(limit=LIMIT_SEQ.format(arg="upto_seq")),
        "scene_graph_at_time": "CREATE OR REPLACE MACRO scene_graph_at_time(upto_ns) AS TABLE "
        + SCENE_GRAPH_BODY.format(limit=LIMIT_TIME.format(arg="upto_ns")),
    }


def _common_views(con: duckdb.DuckDBPyConnection, only: Collection[str] | None = None) -> None:
    """``plans``, ``detections`` and the scene-graph macros (``only``: those named)."""
    for name, ddl in _common_ddl().items():
        if only is None or name in only:
            con.execute(ddl)


#: Words in a query that mean it looks at the catalogue itself: it gets every view.
_CATALOGUE_WORDS: Final = frozenset(
    {
        "information_schema",
        "pg_catalog",
        "duckdb_views",
        "duckdb_tables",
        "duckdb_columns",
        "duckdb_functions",
        "duckdb_dependencies",
        "show",
        "describe",
        "summarize",
        "pragma",
    }
)
_WORD: Final = re.compile(r"[a-z_][a-z0-9_]*")


def _words(text: str) -> set[str]:
    return set(_WORD.findall(text.lower()))


def views_for(sql: str, definitions: Mapping[str, str]) -> set[str] | None:
    """The views and macros (names of ``definitions``: name → its SQL) that ``sql`` reads,
    directly or through others; None if it looks at the catalogue (it gets all). Any word
    of the query that is a view's name counts (a column or a string of that name too): one
    view too many costs a bind, one too few would fail the query."""
    words = _words(sql)
    if words & _CATALOGUE_WORDS:
        return None
    needed: set[str] = set()
    todo = words & definitions.keys()
    while todo:
        name = todo.pop()
        needed.add(name)
        todo |= (_words(definitions[name]) & definitions.keys()) - needed
    return needed


def queryable_names() -> list[str]:
    """What a query over a lake reads by name, sorted: a view per event type, ``events``, the
    derived tables, ``plans`` and ``detections``, and the scene-graph table macros."""
    derived = [spec.name for spec in derived_tables(STORE)]
    return sorted({*STORE.registry.types, "events", *derived, *_common_ddl()})


def open_analytics(
    lake_dir: Path | str,
    *,
    memory_limit: int = DEFAULT_MEMORY_LIMIT,
    threads: int = DEFAULT_THREADS,
    for_sql: str | None = None,
) -> duckdb.DuckDBPyConnection:
    """An in-memory DuckDB with every view over the lake at ``lake_dir``, locked down
    (:func:`~objsearch.events.sql.lock_down`: it reads the lake's folder and nothing else) and
    bounded (:mod:`~objsearch.events.sql_limits`: ``memory_limit`` bytes of buffers, ``threads``,
    spill space in a private temp directory; :func:`run_query` bounds the time).

    ``lake_dir`` is a fleet lake (:func:`objsearch.events.lake.open_lake`): a folder or an ``s3://``
    address. A per-run-folder lake is refused (``objsearch lake upgrade`` migrates it), and so
    is a place that holds no lake. The checks of the table's data files and what a damaged
    one costs the views are :func:`_open_fleet`'s.

    ``for_sql``: make only the views and macros this query reads (what
    ``objsearch query`` does: every view made is bound, which reads its files' footers, so a
    query pays for the views it uses, not for all thirty).
    """
    return _open_fleet(
        open_lake(lake_dir, store=STORE, existing=True),
        memory_limit=memory_limit,
        threads=threads,
        for_sql=for_sql,
    )


def _open_fleet(
    lake: TableLake, *, memory_limit: int, threads: int, for_sql: str | None
) -> duckdb.DuckDBPyConnection:
    """:func:`open_analytics` of the fleet lake (:class:`objsearch.events.lake.TableLake`): views over
    the table's current files, a handful per type once compacted, whatever the number of runs.
    A data file that is missing, of another size than the table's log records, or cut is left
    out with a warning naming it."""
    table = lake.table()
    files, damaged = lake.scan(table)
    for _, why in damaged:
        _log.warning("%s: damaged data file left out of every view: %s", lake.root, why)
    # the table's log against the runs' records: an `add` removed, the newest commit deleted
    # (a damaged `_run` file is among those left out above)
    lake.check_runs(table)
    if lake.remote and len(files) > lake_rewrite.COMPACT_AT_FILES:
        # each file costs requests of its own: 850 small ones took 16.5 s to read, 1.5 s compacted
        _log.warning(
            "%s: %d data files (a commit adds one a type; the next `lake add` compacts past "
            "%d): queries read each; `objsearch lake compact --lake %s` makes few of them",
            lake.root,
            len(files),
            lake_rewrite.COMPACT_AT_FILES,
            lake.root,
        )
    by_kind = {f.kind for f in files}
    # A derived table the runs wrote reads its partition; one none has at this version (older
    # code wrote them) is the same SQL over the events, live.
    live = {
        spec.name: f"SELECT robot, date, run, * EXCLUDE (robot, date, run) FROM ({spec.sql})"
        for spec in derived_tables(STORE)
        if derived_kind(spec.name, spec.version) not in by_kind
    }
    definitions = dict.fromkeys([*STORE.registry.types, "events"], "")
    definitions |= {spec.name: live.get(spec.name, "") for spec in derived_tables(STORE)}
    definitions |= _common_ddl()
    only = None if for_sql is None else views_for(for_sql, definitions)
    con = duckdb.connect(":memory:")
    create_fleet_views(con, lake, files, only)
    for spec in derived_tables(STORE):
        if only is not None and spec.name not in only:
            continue
        kind = derived_kind(spec.name, spec.version)
        body = live.get(spec.name)
        if body is None:
            source = fleet_source(con, lake, kind, [f for f in files if f.kind == kind])
            body = (
                f"SELECT robot, date, run, {quote_ident(derived_column(spec.name))}.* FROM {source}"
            )
        con.execute(f"CREATE OR REPLACE VIEW {spec.name} AS {body}")
    _common_views(con, only)
    apply_limits(con, memory_limit=memory_limit, threads=threads)
    lock_down(con, [] if lake.remote else [Path(lake.root)])
    return con


def run_query(
    con: duckdb.DuckDBPyConnection, sql: str, *, timeout_s: float | None = DEFAULT_TIMEOUT_S
) -> tuple[list[str], list[tuple[Any, ...]]]:
    """Column names and rows of a read-only query (:func:`~objsearch.events.sql.check_read_only`
    refuses anything else with :class:`~objsearch.events.sql.QueryRefusedError`), stopped with
    :class:`~objsearch.events.sql_limits.QueryLimitError` after ``timeout_s`` (None: never), at
    the connection's memory limit, or when the rows it returns would take more than that limit
    (counted as Arrow bytes)."""
    names, batches = stream_query(con, sql, timeout_s=timeout_s, holds_all=True)
    with batches:
        return names, [row for batch in batches for row in batch]


def stream_query(
    con: duckdb.DuckDBPyConnection,
    sql: str,
    *,
    timeout_s: float | None = DEFAULT_TIMEOUT_S,
    holds_all: bool = False,
) -> tuple[list[str], BoundedResult]:
    """As :func:`run_query`, but the rows come in batches as DuckDB produces them, so a huge
    result never sits in memory whole: no batch may take more than the connection's memory limit
    (``holds_all``: all of them together). The time limit runs until the result is closed
    (``with`` it, or :meth:`~objsearch.events.sql_limits.BoundedResult.close`), so it covers what
    the caller does with the rows too (:mod:`objsearch.events.sql_limits`)."""
    check_read_only(con, sql)
    result = BoundedResult(con, sql, Deadline(con, timeout_s), holds_all=holds_all)
    return result.names, result
