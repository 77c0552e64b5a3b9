"""The analysts' DuckDB: the lake's per-type views plus convenience views and the scene graph.

Convenience views (one row per …):

* ``searches`` — task: target, start, scene, method, update mode, success, path length, duration,
  rooms planned, detections, found instance, ``task_index`` (1, 2, … within the run).
* ``plans`` — ``plan_computed``: the task's target, room, ``room_rank`` within the task,
  ``chosen_order`` (static ids), ``first_choice``, candidates, WPL value.
* ``detections`` — ``detection``: the task's target, ``is_target``, position ``x, y, z``, the
  nearest static object (``static_id``, ``static_class``) and ``at_static``.
* ``scene_graph`` — (robot, run, dynamic, static): Rel at the end of each run.

Table macros ``scene_graph_at_seq(s)`` and ``scene_graph_at_time(t_ns)`` give Rel as it was right
after seq ``s`` (or the last event with ``time_ns <= t_ns``) of every run, computed with the closed
form of Eq. 4 instead of a fold: a pair's value after k updates of its dynamic class is

    Rel_k = Rel_0 / 2^k + Σ_j [o_d seen at o_s in update j] / 2^(k - j + 1),

i.e. each update halves everything before it and the update that saw o_d at o_s adds 1/2. Which
task ends count as updates of o_d follows :class:`objsearch.agent.scene_graph.SceneGraphProjection`
exactly: the update mode of the latest ``run_started``, the experience of the accepted detections
since the task began, the prior of the latest ``scene_graph_seeded`` (tested against the fold).
"""

from __future__ import annotations

from pathlib import Path
from typing import Final

import duckdb
from objsearch.events.lake import Lake
from objsearch.events.sql import connect

_SEARCHES: Final = """
CREATE OR REPLACE VIEW searches AS
WITH plans_per_task AS (
    SELECT robot, run, task_id, count(*) AS rooms_planned FROM plan_computed GROUP BY ALL
), detections_per_task AS (
    SELECT robot, run, task_id, count(*) AS detections FROM detection GROUP BY ALL
)
SELECT s.robot, s.date, s.run, s.task_id,
       row_number() OVER (PARTITION BY s.robot, s.run ORDER BY s.seq) AS task_index,
       s.target, s.start, s.scene, r.method, r.update_mode, r.alpha,
       s.seq AS start_seq, e.seq AS end_seq, s.time_ns AS start_ns, e.time_ns AS end_ns,
       (e.time_ns - s.time_ns) / 1e9 AS duration_s,
       e.success, e.path_length,
       coalesce(p.rooms_planned, 0) AS rooms_planned,
       coalesce(d.detections, 0) AS detections,
       f.instance_id AS found_instance
FROM task_started s
LEFT JOIN task_ended e USING (robot, run, task_id)
LEFT JOIN plans_per_task p USING (robot, run, task_id)
LEFT JOIN detections_per_task d USING (robot, run, task_id)
LEFT JOIN target_found f USING (robot, run, task_id)
ASOF LEFT JOIN run_started r ON s.robot = r.robot AND s.run = r.run AND s.seq > r.seq
"""

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

# {limit} selects, per run, the last seq to count: the closed form of Eq. 4 over what came before.
_SCENE_GRAPH_BODY: Final = """
WITH limits AS (
    {limit}
), seeds AS (
    SELECT g.robot, g.run, max(g.seq) AS seed_seq
    FROM scene_graph_seeded g JOIN limits l ON g.robot = l.robot AND g.run = l.run
    WHERE g.seq <= l.upto GROUP BY ALL
), prior AS (
    SELECT g.robot, g.run, s.seed_seq, v.dynamic, v.static, v.rel AS rel0
    FROM (SELECT robot, run, seq, unnest("values") AS v FROM scene_graph_seeded) g
    JOIN seeds s ON g.robot = s.robot AND g.run = s.run AND g.seq = s.seed_seq
), known AS (
    SELECT DISTINCT robot, run, dynamic FROM prior
), bounds AS (  -- the experience pool is emptied at every task start and task end
    SELECT robot, run, seq, target, true AS is_start FROM task_started
    UNION ALL
    SELECT robot, run, seq, NULL AS target, false AS is_start FROM task_ended
), all_ends AS (  -- each task end with its task's target (the ASOF joins come first: fast)
    SELECT e.robot, e.run, e.seq AS end_seq, CASE WHEN b.is_start THEN b.target END AS target
    FROM task_ended e
    ASOF LEFT JOIN bounds b ON e.robot = b.robot AND e.run = b.run AND e.seq > b.seq
), all_moded AS (
    SELECT e.*, coalesce(r.update_mode, 'all') AS mode
    FROM all_ends e
    ASOF LEFT JOIN run_started r ON e.robot = r.robot AND e.run = r.run AND e.end_seq > r.seq
), moded AS (  -- ... then only those after the seed and within the limit
    SELECT m.*
    FROM all_moded m
    JOIN seeds s ON m.robot = s.robot AND m.run = s.run
    JOIN limits l ON m.robot = l.robot AND m.run = l.run
    WHERE m.end_seq > s.seed_seq AND m.end_seq <= l.upto
), seen AS (  -- accepted detections, each attributed to the next boundary if it is a task end
    SELECT d.robot, d.run, b.seq AS end_seq, d.object_class AS dynamic,
           CASE WHEN d.support."at" THEN d.support.static_class END AS static
    FROM detection d
    ASOF JOIN bounds b ON d.robot = b.robot AND d.run = b.run AND d.seq < b.seq
    WHERE d.accepted AND NOT b.is_start
), updates AS (  -- (run, dynamic class, task end) where Eq. 4 updated the class
    SELECT DISTINCT m.robot, m.run, m.end_seq, x.dynamic
    FROM moded m
    JOIN seen x ON m.robot = x.robot AND m.run = x.run AND m.end_seq = x.end_seq
    JOIN known k ON k.robot = x.robot AND k.run = x.run AND k.dynamic = x.dynamic
    WHERE m.mode = 'all' OR (m.mode = 'targets' AND x.dynamic = m.target)
), aged AS (  -- age 1 = the class's latest update, 2 = the one before, ...
    SELECT *, row_number() OVER (PARTITION BY robot, run, dynamic ORDER BY end_seq DESC) AS age
    FROM updates
), counts AS (
    SELECT robot, run, dynamic, count(*) AS k FROM aged GROUP BY ALL
), gains AS (
    SELECT a.robot, a.run, a.dynamic, h.static, sum(pow(0.5, a.age)) AS gain
    FROM aged a
    JOIN (SELECT DISTINCT robot, run, end_seq, dynamic, static FROM seen WHERE static IS NOT NULL) h
      ON a.robot = h.robot AND a.run = h.run AND a.end_seq = h.end_seq AND a.dynamic = h.dynamic
    GROUP BY ALL
)
SELECT p.robot, p.run, p.dynamic, p.static,
       p.rel0 * pow(0.5, coalesce(c.k, 0)) + coalesce(g.gain, 0.0) AS rel,
       coalesce(c.k, 0) AS updates, p.rel0 AS prior
FROM prior p
LEFT JOIN counts c ON p.robot = c.robot AND p.run = c.run AND p.dynamic = c.dynamic
LEFT JOIN gains g
  ON p.robot = g.robot AND p.run = g.run AND p.dynamic = g.dynamic AND p.static = g.static
"""

_LIMIT_SEQ: Final = (
    "SELECT robot, run, max(seq) AS upto FROM events WHERE seq <= {arg} GROUP BY robot, run"
)
_LIMIT_TIME: Final = (
    "SELECT robot, run, max(seq) AS upto FROM events WHERE time_ns <= {arg} GROUP BY robot, run"
)


def create_views(con: duckdb.DuckDBPyConnection) -> None:
    """Add the convenience views and scene-graph macros to a connection with the type views."""
    for ddl in (_SEARCHES, _PLANS, _DETECTIONS):
        con.execute(ddl)
    con.execute(
        "CREATE OR REPLACE MACRO scene_graph_at_seq(upto_seq) AS TABLE "
        + _SCENE_GRAPH_BODY.format(limit=_LIMIT_SEQ.format(arg="upto_seq"))
    )
    con.execute(
        "CREATE OR REPLACE MACRO scene_graph_at_time(upto_ns) AS TABLE "
        + _SCENE_GRAPH_BODY.format(limit=_LIMIT_TIME.format(arg="upto_ns"))
    )
    con.execute(
        "CREATE OR REPLACE VIEW scene_graph AS "
        + _SCENE_GRAPH_BODY.format(
            limit="SELECT robot, run, max(seq) AS upto FROM events GROUP BY robot, run"
        )
    )


def open_analytics(lake_dir: Path | str) -> duckdb.DuckDBPyConnection:
    """An in-memory DuckDB with every view over the lake at ``lake_dir``."""
    con = connect(Lake(lake_dir))
    create_views(con)
    return con
