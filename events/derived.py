"""Derived tables of a run: per-run summaries the lake writes next to the events when it commits.

A committed run never changes, so anything computed from its events alone is as trustworthy as
the events themselves and need not be recomputed by every query. The analytics views
(:mod:`objsearch.replay.analytics`) read these small files instead of joining millions of event
rows; for a run without them (a lake written by older code) the views compute the same rows
from the events with the very same SQL, so the answer never depends on which path was taken.

Each table is a :class:`DerivedTable`: a name, a version and one SQL query over the per-type
event views (``task_started``, ``detection``, … each with ``robot``, ``date`` and ``run``
columns). The query is the only definition: :func:`derive_run` runs it over one run's Arrow
tables at commit time, and the analytics views run it over the lake's views for runs that lack
the file. The file is ``RUN/_derived/<name>.v<version>.parquet``; bump ``version`` whenever the
query's meaning changes, and runs holding an older version fall back to the live query until
they are upgraded (:meth:`objsearch.events.lake.Lake.upgrade`).

Which tables a run has is the store's catalogue's to say (:func:`derived_tables`): the store
knows :data:`SEARCHES`, the per-task summary, and is handed the domain's others with its
:class:`~objsearch.events.catalogue.Catalogue` — the agent's are Eq. 4's ``eq4_updates`` and
``scene_graph`` (:mod:`objsearch.agent.scene_graph_sql`, beside the fold they restate), so this
layer holds no formula of the paper's.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Final

from .catalogue import DERIVED_DIR, DerivedTable
from .store import Store

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = ["DERIVED_DIR", "PARTITION_NAMES", "RUN_MODES", "SEARCHES", "DerivedTable"]

#: Columns a derived file does not store: the lake's partition columns supply them.
PARTITION_NAMES: Final = ("robot", "date", "run")


# The run's update mode at a given seq: the latest run_started before it (``searches`` and the
# agent's ``eq4_updates`` join it). A range join on the next run_started's seq is one hash join
# on (robot, run); an ASOF join sorts both sides.
RUN_MODES: Final = """
    SELECT robot, run, seq, method, update_mode, alpha,
           lead(seq) OVER (PARTITION BY robot, run ORDER BY seq) AS next_seq
    FROM run_started
"""

SEARCHES: Final = DerivedTable(
    "searches",
    4,
    f"""
WITH plans_per_task AS (
    SELECT robot, run, task_id, count(*) AS rooms_planned FROM plan_computed GROUP BY ALL
), detections_per_task AS (
    SELECT robot, run, task_id, count(*) AS detections FROM detection GROUP BY ALL
), modes AS ({RUN_MODES}
), ends AS (  -- a task ends, or a crash left it open and the restart aborted it (one row a task)
    SELECT robot, run, task_id, seq, time_ns, success, path_length, false AS aborted
    FROM task_ended
    UNION ALL
    SELECT robot, run, task_id, seq, time_ns, false, path_length, true FROM task_aborted
)
SELECT s.robot, s.date, s.run, s.task_id,
       row_number() OVER (PARTITION BY s.robot, s.run ORDER BY s.seq) AS task_index,
       s.target, s.start, s.scene,
       -- the local time of day the search began (v4; NULL in a log that records none:
       -- task_started v1, runs without a time of day): 0 Monday … 6 Sunday, minute after midnight
       s.clock.weekday AS clock_weekday, s.clock.minute AS clock_minute,
       r.method, r.update_mode, r.alpha,
       s.seq AS start_seq, e.seq AS end_seq, s.time_ns AS start_ns, e.time_ns AS end_ns,
       (e.time_ns - s.time_ns) / 1e9 AS duration_s,
       e.success, e.path_length,
       -- the paper's metric: metres to the detection; a failed or aborted search never
       -- discovered it, so its whole path counts; NULL for a success logged before v3 of this
       -- table (no target_detected event then), rather than a guess
       coalesce(t.path_length, CASE WHEN NOT e.success THEN e.path_length END)
           AS path_to_discovery,
       e.aborted,
       coalesce(p.rooms_planned, 0) AS rooms_planned,
       coalesce(d.detections, 0) AS detections,
       f.instance_id AS found_instance
FROM task_started s
LEFT JOIN ends e USING (robot, run, task_id)
LEFT JOIN plans_per_task p USING (robot, run, task_id)
LEFT JOIN detections_per_task d USING (robot, run, task_id)
LEFT JOIN target_found f USING (robot, run, task_id)
LEFT JOIN target_detected t USING (robot, run, task_id)
LEFT JOIN modes r
  ON s.robot = r.robot AND s.run = r.run AND s.seq > r.seq
 AND (r.next_seq IS NULL OR s.seq < r.next_seq)
""",
    order_by="start_seq",
)


def derived_tables(store: Store) -> tuple[DerivedTable, ...]:
    """Every derived table in dependency order: :data:`SEARCHES`, then the store's catalogue's
    (:attr:`objsearch.events.catalogue.Catalogue.derived`; the agent's are Eq. 4's)."""
    return (SEARCHES, *store.catalogue.derived)


def derive_run(
    tables: Mapping[str, pa.Table],
    *,
    robot: str,
    date: str | dt.date,
    run: str,
    store: Store,
) -> dict[str, pa.Table]:
    """Every derived table of one run from its event tables (one per type; missing types are
    empty), without the partition columns, sorted as the query orders them."""
    # Imported here, not above: a catalogue declares its tables with this module (the robot's
    # too), and DuckDB and Arrow take most of a second to import.
    import duckdb
    import pyarrow as pa

    from .arrow import event_schema

    # One thread: a parallel SUM of doubles adds in whatever order the threads finish, so the
    # same run could derive a file that differs in its last bits (seen: searches.v3.parquet one
    # byte longer on a busy machine), and the file's recorded digest would not reproduce.
    con = duckdb.connect(":memory:", config={"threads": 1})
    try:
        day = date.isoformat() if isinstance(date, dt.date) else date
        for event_type in store.registry.types:
            table = tables.get(event_type)
            if table is None:
                table = pa.Table.from_pylist([], schema=event_schema(event_type, store))
            con.register(f"_arrow_{event_type}", table)
            con.execute(
                f'CREATE VIEW "{event_type}" AS SELECT *, {_literal(robot)}::VARCHAR AS robot, '
                f"{_literal(day)}::DATE AS date, {_literal(run)}::VARCHAR AS run "
                f'FROM "_arrow_{event_type}"'
            )
        return derive_views(con, store)
    finally:
        con.close()


def derive_views(con: Any, store: Store) -> dict[str, pa.Table]:
    """Every derived table of ``store``'s catalogue from a DuckDB connection whose per-type
    views (with ``robot``, ``date``, ``run``) hold one run, without the partition columns."""
    out: dict[str, pa.Table] = {}
    for derived in derived_tables(store):
        table = con.sql(
            f"SELECT * FROM ({derived.sql}) ORDER BY {derived.order_by}"
        ).to_arrow_table()
        # A later table may read an earlier one (scene_graph reads eq4_updates).
        con.register(derived.name, table)
        out[derived.name] = table.drop_columns(list(PARTITION_NAMES))
    return out


def _literal(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"
