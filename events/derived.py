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

The SQL lives here, beside the lake that writes it, because the lake cannot import the agent. It
restates the boundaries :class:`objsearch.agent.scene_graph.SceneGraphProjection` folds (tests in
``tests/replay`` check the closed form built on it against the fold). The closed form is Eq. 4's
only: a run whose spec (``run_started.relations``) names another relation model (the Beta
posterior) has no rows in ``scene_graph`` — it is folded by ``objsearch graph`` and replay, which
build its model from the spec — rather than rows that would say something the robot never knew.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping
from pathlib import Path
from typing import Final, NamedTuple

import duckdb
import pyarrow as pa

from .arrow import event_schema
from .schemas import default_registry

DERIVED_DIR: Final = "_derived"
#: Columns a derived file does not store: the lake's partition columns supply them.
PARTITION_NAMES: Final = ("robot", "date", "run")


class DerivedTable(NamedTuple):
    name: str
    version: int
    sql: str  # over the per-type views; returns robot, date, run and the table's columns

    @property
    def file_name(self) -> str:
        return f"{self.name}.v{self.version}.parquet"

    def path(self, run_dir: Path) -> Path:
        return run_dir / DERIVED_DIR / self.file_name


# The run's update mode at a given seq: the latest run_started before it. A range join on the
# next run_started's seq is one hash join on (robot, run); an ASOF join sorts both sides.
_MODES: Final = """
    SELECT robot, run, seq, method, update_mode, alpha,
           lead(seq) OVER (PARTITION BY robot, run ORDER BY seq) AS next_seq
    FROM run_started
"""

SEARCHES: Final = DerivedTable(
    "searches",
    3,
    f"""
WITH plans_per_task AS (
    SELECT robot, run, task_id, count(*) AS rooms_planned FROM plan_computed GROUP BY ALL
), detections_per_task AS (
    SELECT robot, run, task_id, count(*) AS detections FROM detection GROUP BY ALL
), modes AS ({_MODES}
), ends AS (  -- a task ends, or a crash left it open and the restart aborted it (one row a task)
    SELECT robot, run, task_id, seq, time_ns, success, path_length, false AS aborted
    FROM task_ended
    UNION ALL
    SELECT robot, run, task_id, seq, time_ns, false, path_length, true FROM task_aborted
)
SELECT s.robot, s.date, s.run, s.task_id,
       row_number() OVER (PARTITION BY s.robot, s.run ORDER BY s.seq) AS task_index,
       s.target, s.start, s.scene, r.method, r.update_mode, r.alpha,
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
)

# One row per (task end, semi-dynamic class) where Eq. 4 updates the class, whatever the scene
# graph then holds: the class's experience since the task began (accepted detections after the
# last task start or end), chosen by the update mode of the latest run_started (all: every class
# seen; targets: the task's target if seen; none: nothing — the SQL twin of the agent's
# ``scene_graph.experience_to_fold``; change both together). ``n`` numbers a class's updates
# 1, 2, … within the run, so the closed form can age them for any cut-off and any seed without
# ranking them again; ``statics`` are the static classes the class was seen at. Which classes the
# prior knows, and which updates fall after the seed in force, depend on the cut-off and are
# applied by the closed form (objsearch.replay.analytics).
EQ4_UPDATES: Final = DerivedTable(
    "eq4_updates",
    2,
    f"""
WITH bounds AS (  -- the experience pool is emptied at every task start, end and abort
    SELECT robot, run, seq, target, true AS is_start, false AS is_abort FROM task_started
    UNION ALL
    SELECT robot, run, seq, NULL AS target, false AS is_start, false FROM task_ended
    UNION ALL  -- an aborted task folds nothing
    SELECT robot, run, seq, NULL AS target, false AS is_start, true FROM task_aborted
), ends AS (  -- each task end with its task's target (NULL if the end follows another end)
    SELECT e.robot, e.date, e.run, e.seq AS end_seq,
           CASE WHEN b.is_start THEN b.target END AS target
    FROM task_ended e
    ASOF LEFT JOIN bounds b ON e.robot = b.robot AND e.run = b.run AND e.seq > b.seq
), modes AS ({_MODES}
), moded AS (
    SELECT e.*, coalesce(r.update_mode, 'all') AS mode
    FROM ends e
    LEFT JOIN modes r
      ON e.robot = r.robot AND e.run = r.run AND e.end_seq > r.seq
     AND (r.next_seq IS NULL OR e.end_seq < r.next_seq)
), seen AS (  -- accepted detections, each attributed to the next boundary if it is a task end
    SELECT d.robot, d.run, b.seq AS end_seq, d.object_class AS dynamic,
           CASE WHEN d.support."at" THEN d.support.static_class END AS static
    FROM detection d
    ASOF JOIN bounds b ON d.robot = b.robot AND d.run = b.run AND d.seq < b.seq
    WHERE d.accepted AND NOT b.is_start AND NOT b.is_abort
), updates AS (
    SELECT m.robot, m.date, m.run, m.end_seq, x.dynamic,
           coalesce(list_sort(list_distinct(list(x.static))), []::VARCHAR[]) AS statics
    FROM moded m
    JOIN seen x ON m.robot = x.robot AND m.run = x.run AND m.end_seq = x.end_seq
    WHERE m.mode = 'all' OR (m.mode = 'targets' AND x.dynamic = m.target)
    GROUP BY ALL
)
SELECT robot, date, run, end_seq, dynamic,
       row_number() OVER (PARTITION BY robot, run, dynamic ORDER BY end_seq) AS n, statics
FROM updates
""",
)

# {limit} gives, per run, the last seq to count: the closed form of Eq. 4 over what came before.
# The update rows (``eq4_updates``: which task end updated which class, the class's update number
# n and the static classes it was seen at) are derived once per run when it is committed; here
# only the cut-off and the seed are applied, so no query re-attributes millions of detections.
# The same text serves the analytics macros (any cut-off) and the derived ``scene_graph`` table
# (the end of the run), so the two cannot drift apart.
SCENE_GRAPH_BODY: Final = """
WITH limits AS (
    {limit}
), folds AS (  -- the relation model of the run's first run_started: this form is Eq. 4's only
    SELECT robot, run, arg_min(relations.model, seq) AS model FROM run_started GROUP BY ALL
), seeds AS (  -- the seed in force at the cut-off
    SELECT g.robot, g.run, max(g.seq) AS seed_seq, any_value(l.upto) AS upto
    FROM scene_graph_seeded g JOIN limits l ON g.robot = l.robot AND g.run = l.run
    JOIN folds f ON g.robot = f.robot AND g.run = f.run
    WHERE g.seq <= l.upto AND f.model = 'eq4' GROUP BY g.robot, g.run
), prior AS (
    SELECT g.robot, g.date, g.run, v.dynamic, v.static, v.rel AS rel0
    FROM (SELECT robot, date, run, seq, unnest("values") AS v FROM scene_graph_seeded) g
    JOIN seeds s ON g.robot = s.robot AND g.run = s.run AND g.seq = s.seed_seq
), upd AS (  -- the updates up to the cut-off
    SELECT u.robot, u.run, u.dynamic, u.end_seq, u.n, u.statics, s.seed_seq
    FROM eq4_updates u JOIN seeds s ON u.robot = s.robot AND u.run = s.run
    WHERE u.end_seq <= s.upto
), counts AS (  -- k = updates since the seed = the last n minus the last n before the seed
    SELECT robot, run, dynamic, max(n) AS last_n,
           coalesce(max(n) FILTER (WHERE end_seq <= seed_seq), 0) AS seed_n
    FROM upd GROUP BY ALL
), gains AS (  -- age = last_n - n + 1: 1 for the class's latest update, 2 for the one before, ...
    SELECT h.robot, h.run, h.dynamic, h.static, sum(pow(0.5, c.last_n - h.n + 1)) AS gain
    FROM (
        SELECT robot, run, dynamic, n, unnest(statics) AS static FROM upd WHERE end_seq > seed_seq
    ) h
    JOIN counts c ON h.robot = c.robot AND h.run = c.run AND h.dynamic = c.dynamic
    GROUP BY ALL
)
SELECT p.robot, p.date, p.run, p.dynamic, p.static,
       p.rel0 * pow(0.5, coalesce(c.last_n - c.seed_n, 0)) + coalesce(g.gain, 0.0) AS rel,
       coalesce(c.last_n - c.seed_n, 0) AS updates, p.rel0 AS prior
FROM prior p
LEFT JOIN counts c ON p.robot = c.robot AND p.run = c.run AND p.dynamic = c.dynamic
LEFT JOIN gains g
  ON p.robot = g.robot AND p.run = g.run AND p.dynamic = g.dynamic AND p.static = g.static
"""

# A cut-off at seq s counts exactly the events with seq <= s, so s itself serves (no scan of
# every event for max(seq) <= s); a run with nothing at or before s has no seed and no rows.
LIMIT_SEQ: Final = "SELECT DISTINCT robot, run, {arg} AS upto FROM scene_graph_seeded"
LIMIT_TIME: Final = (
    "SELECT robot, run, max(seq) AS upto FROM events WHERE time_ns <= {arg} GROUP BY robot, run"
)
LIMIT_NONE: Final = (
    "SELECT DISTINCT robot, run, 9223372036854775807::BIGINT AS upto FROM scene_graph_seeded"
)

# The graph at the end of the run: a committed run has no later events, so this is final.
SCENE_GRAPH: Final = DerivedTable("scene_graph", 2, SCENE_GRAPH_BODY.format(limit=LIMIT_NONE))

DERIVED_TABLES: Final = (SEARCHES, EQ4_UPDATES, SCENE_GRAPH)  # in dependency order


def derive_run(
    tables: Mapping[str, pa.Table], *, robot: str, date: str | dt.date, run: str
) -> dict[str, pa.Table]:
    """Every derived table of one run from its event tables (one per type; missing types are
    empty), without the partition columns, sorted as the query orders them."""
    con = duckdb.connect(":memory:")
    try:
        day = date.isoformat() if isinstance(date, dt.date) else date
        for event_type in default_registry().types:
            table = tables.get(event_type)
            if table is None:
                table = pa.Table.from_pylist([], schema=event_schema(event_type))
            con.register(f"_arrow_{event_type}", table)
            con.execute(
                f'CREATE VIEW "{event_type}" AS SELECT *, {_literal(robot)}::VARCHAR AS robot, '
                f"{_literal(day)}::DATE AS date, {_literal(run)}::VARCHAR AS run "
                f'FROM "_arrow_{event_type}"'
            )
        out: dict[str, pa.Table] = {}
        for derived in DERIVED_TABLES:
            table = con.sql(
                f"SELECT * FROM ({derived.sql}) ORDER BY {_ORDER[derived.name]}"
            ).to_arrow_table()
            # A later table may read an earlier one (scene_graph reads eq4_updates).
            con.register(derived.name, table)
            out[derived.name] = table.drop_columns(list(PARTITION_NAMES))
        return out
    finally:
        con.close()


_ORDER: Final = {
    "searches": "start_seq",
    "eq4_updates": "end_seq, dynamic",
    "scene_graph": "dynamic, static",
}


def _literal(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"
