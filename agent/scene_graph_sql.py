"""Eq. 4 in SQL: the lake's ``eq4_updates`` and ``scene_graph`` tables, beside the fold.

:class:`~objsearch.agent.scene_graph.SceneGraphProjection` is the definition of Eq. 4; this module
is its closed form over the lake's per-type event views, so analytics need not fold millions of
events (``tests/replay/test_analytics.py`` checks the two agree). It lives in the agent, not in
``events/``, so that a change to Eq. 4 touches one package: the event store knows no formula and
is handed these tables with the agent's catalogue (:data:`DERIVED_TABLES`, installed by the
``objsearch`` package), and :mod:`objsearch.replay.analytics` builds its ``scene_graph_at_seq`` /
``scene_graph_at_time`` macros from :data:`SCENE_GRAPH_BODY` with :data:`LIMIT_SEQ` and
:data:`LIMIT_TIME`.

The closed form is Eq. 4's only: a run whose spec (``run_started.relations``) names another
relation model (the Beta posterior) has no rows in ``scene_graph`` — it is folded by ``objsearch
graph`` and replay, which build its model from the spec — rather than rows that would say
something the robot never knew. Bump a table's ``version`` whenever its query's meaning changes
(see :mod:`objsearch.events.derived`).
"""

from __future__ import annotations

from typing import Final

from objsearch.events.derived import RUN_MODES, DerivedTable

# One row per (task end, semi-dynamic class) where Eq. 4 updates the class, whatever the scene
# graph then holds: the class's experience since the task began (accepted detections after the
# last task start or end), chosen by the update mode of the latest run_started (all: every class
# seen; targets: the task's target if seen; none: nothing — the SQL twin of
# ``scene_graph.experience_to_fold``; change both together). ``n`` numbers a class's updates 1, 2,
# … within the run, so the closed form can age them for any cut-off and any seed without ranking
# them again; ``statics`` are the static classes the class was seen at. Which classes the prior
# knows, and which updates fall after the seed in force, depend on the cut-off and are applied by
# the closed form (SCENE_GRAPH_BODY).
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
), modes AS ({RUN_MODES}
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
    order_by="end_seq, dynamic",
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
SCENE_GRAPH: Final = DerivedTable(
    "scene_graph", 2, SCENE_GRAPH_BODY.format(limit=LIMIT_NONE), order_by="dynamic, static"
)

#: The agent's derived tables, in dependency order (``scene_graph`` reads ``eq4_updates``).
DERIVED_TABLES: Final = (EQ4_UPDATES, SCENE_GRAPH)
