"""The analytics views: the closed-form scene graph equals the fold; the documented queries run."""

from __future__ import annotations

import json
import re
from pathlib import Path

import duckdb
import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.scene_graph import SceneGraphProjection
from objsearch.cli import main
from objsearch.events import fold, read_log
from objsearch.events.derived import derived_tables
from objsearch.events.lake import TableLake
from objsearch.replay.analytics import open_analytics

DOC = Path(__file__).resolve().parents[2] / "docs" / "analytics.md"
QUESTIONS = re.findall(r"### (\d+)\. [^\n]*\n.*?```sql\n(.*?)```", DOC.read_text(), re.S)


@pytest.fixture(scope="module")
def con(lake: TableLake) -> duckdb.DuckDBPyConnection:
    return open_analytics(lake.root)


def test_the_doc_has_ten_questions_at_least() -> None:
    assert len(QUESTIONS) >= 10
    assert [int(n) for n, _ in QUESTIONS] == list(range(1, len(QUESTIONS) + 1))


@pytest.mark.parametrize(("number", "sql"), QUESTIONS, ids=[f"Q{n}" for n, _ in QUESTIONS])
def test_every_documented_query_runs_and_answers(
    con: duckdb.DuckDBPyConnection, number: str, sql: str
) -> None:
    rows = con.execute(sql).fetchall()
    assert rows, f"question {number} returned no rows"


def _graph_sql(con: duckdb.DuckDBPyConnection, run: str, seq: int) -> dict[tuple[str, str], float]:
    rows = con.execute(
        "SELECT dynamic, static, rel FROM scene_graph_at_seq(?) WHERE run = ?", [seq, run]
    ).fetchall()
    return {(d, s): r for d, s, r in rows}


@pytest.mark.parametrize("run", ["robot", "targets"])
def test_closed_form_equals_the_fold_at_every_task_end(
    con: duckdb.DuckDBPyConnection, logs: dict[str, Path], run: str
) -> None:
    events = list(read_log(logs[run], store=STORE))
    checkpoints = [e.seq for e in events if e.type in ("task_ended", "scene_graph_seeded")]
    checkpoints += [events[-1].seq, checkpoints[-1] - 1]
    changed = 0
    for seq in checkpoints:
        graph = fold(iter(events), SceneGraphProjection(), until_seq=seq)
        sql = _graph_sql(con, run, seq)
        assert sql.keys() == graph.relations.keys()
        for pair, value in graph.relations.items():
            assert sql[pair] == pytest.approx(value, abs=1e-12), (seq, pair)
        prior = _graph_sql(con, run, checkpoints[0])
        changed += sum(abs(sql[k] - prior[k]) > 1e-9 for k in prior)
    assert changed > 0  # the updates moved the graph, so the comparison means something


@pytest.mark.parametrize("run", ["robot", "targets"])
def test_scene_graph_is_the_fold_of_the_whole_run(
    con: duckdb.DuckDBPyConnection, logs: dict[str, Path], run: str
) -> None:
    graph = fold(read_log(logs[run], store=STORE), SceneGraphProjection())
    rows = con.execute(
        "SELECT dynamic, static, rel, updates FROM scene_graph WHERE run = ?", [run]
    ).fetchall()
    assert {(d, s) for d, s, _, _ in rows} == graph.relations.keys()
    for d, s, rel, _ in rows:
        assert rel == pytest.approx(graph.relations[d, s], abs=1e-12), (d, s)
    assert sum(u for *_, u in rows) > 0


def test_targets_mode_updates_only_targets(con: duckdb.DuckDBPyConnection) -> None:
    updated = {
        d
        for (d,) in con.execute(
            "SELECT DISTINCT dynamic FROM scene_graph WHERE run = 'targets' AND updates > 0"
        ).fetchall()
    }
    assert updated == {"Phone", "Cup", "Vase"}


def test_scene_graph_as_of_time_matches_as_of_seq(
    con: duckdb.DuckDBPyConnection, logs: dict[str, Path]
) -> None:
    events = list(read_log(logs["robot"], store=STORE))
    ended = [e for e in events if e.type == "task_ended"][5]
    last_at_time = max(e.seq for e in events if e.time_ns <= ended.time_ns)
    by_time = con.execute(
        "SELECT dynamic, static, rel FROM scene_graph_at_time(?) WHERE run = 'robot'",
        [ended.time_ns],
    ).fetchall()
    assert {(d, s): r for d, s, r in by_time} == _graph_sql(con, "robot", last_at_time)


def test_searches_agree_with_the_log(con: duckdb.DuckDBPyConnection, logs: dict[str, Path]) -> None:
    ended = [e for e in read_log(logs["targets"], store=STORE) if e.type == "task_ended"]
    rows = con.execute(
        "SELECT task_id, target, success, path_length, method, update_mode FROM searches "
        "WHERE run = 'targets' ORDER BY task_index"
    ).fetchall()
    assert [(r[0], r[1], r[2], r[3]) for r in rows] == [
        (e.task_id, e.payload["target"], e.payload["success"], e.payload["path_length"])
        for e in ended
    ]
    assert {(r[4], r[5]) for r in rows} == {("rvp", "targets")}
    started = [e for e in read_log(logs["targets"], store=STORE) if e.type == "task_started"]
    clocks = con.execute(
        "SELECT clock_weekday, clock_minute FROM searches WHERE run = 'targets' ORDER BY task_index"
    ).fetchall()
    assert clocks == [
        (e.payload["clock"]["weekday"], e.payload["clock"]["minute"]) for e in started
    ]
    # The v1 log's task_started records no time of day: NULL, not a guess.
    nulls = con.execute(
        "SELECT count(*), count(clock_weekday), count(clock_minute) FROM searches "
        "WHERE run = 'robot'"
    ).fetchone()
    assert nulls is not None and nulls[0] > 0 and nulls[1:] == (0, 0)
    walked = con.execute(
        "SELECT max(abs(s.path_length - m.walked)) FROM searches s JOIN (SELECT run, task_id, "
        "sum(metres) AS walked FROM moved GROUP BY ALL) m USING (run, task_id)"
    ).fetchone()
    assert walked is not None and walked[0] < 1e-3


def test_plans_keep_the_chosen_order(con: duckdb.DuckDBPyConnection, logs: dict[str, Path]) -> None:
    plans = [e for e in read_log(logs["robot"], store=STORE) if e.type == "plan_computed"]
    rows = con.execute(
        "SELECT seq, chosen_order, first_choice, candidates FROM plans WHERE run = 'robot' "
        "ORDER BY seq"
    ).fetchall()
    assert [(r[0], r[1], r[3]) for r in rows] == [
        (e.seq, list(e.payload["order"]), len(e.payload["candidates"])) for e in plans
    ]
    assert all(r[2] == (r[1][0] if r[1] else None) for r in rows)


# --- derived tables --------------------------------------------------------------------------


def test_derived_tables_equal_the_live_query(con: duckdb.DuckDBPyConnection) -> None:
    # What a lake whose runs lack a derived table at its version (older code wrote them) reads:
    # the same SQL over the events, live (replay/analytics.py: _open_fleet).
    for spec, key in zip(
        derived_tables(STORE),
        ("run, task_index", "run, end_seq, dynamic", "run, dynamic, static"),
        strict=True,
    ):
        live = f"SELECT robot, date, run, * EXCLUDE (robot, date, run) FROM ({spec.sql})"
        # Sums may add in another order per run than over the lake: Rel to 1e-12.
        columns = "* REPLACE (round(rel, 12) AS rel)" if spec.name == "scene_graph" else "*"
        stored = con.execute(f"SELECT {columns} FROM {spec.name} ORDER BY {key}")
        rows, names = stored.fetchall(), [d[0] for d in stored.description]
        computed = con.execute(f"SELECT {columns} FROM ({live}) ORDER BY {key}")
        assert rows and rows == computed.fetchall(), spec.name
        assert names == [d[0] for d in computed.description]


# --- the command line ----------------------------------------------------------------------------


def test_query_formats(lake: TableLake, capsys: pytest.CaptureFixture[str]) -> None:
    sql = "SELECT target, count(*) AS n FROM searches WHERE run = 'robot' GROUP BY 1 ORDER BY 1"
    assert main(["query", "--lake", str(lake.root), sql, "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out) == [
        {"target": "Apple", "n": 4},
        {"target": "Bowl", "n": 4},
        {"target": "Cup", "n": 4},
    ]
    assert main(["query", "--lake", str(lake.root), sql, "--format", "csv"]) == 0
    assert capsys.readouterr().out == "target,n\nApple,4\nBowl,4\nCup,4\n"
    assert main(["query", "--lake", str(lake.root), sql]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].split() == ["target", "n"] and out[-1] == "(3 rows)"


def test_query_errors_are_clear(
    lake: TableLake, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["query", "--lake", str(lake.root), "SELECT nope FROM searches"]) == 2
    assert "query failed" in capsys.readouterr().err
    assert main(["query", "--lake", str(tmp_path / "missing"), "SELECT 1"]) == 2
    assert "no lake at" in capsys.readouterr().err


def test_lake_add_and_ls(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from .conftest import V1_LOG

    lake = str(tmp_path / "lake")
    assert main(["lake", "add", str(V1_LOG), "--robot", "r1", "--lake", lake]) == 0
    assert "812 events" in capsys.readouterr().out
    # The same log under a second run name would count its events twice: refused, named.
    assert (
        main(["lake", "add", str(V1_LOG), "--robot", "r1", "--run", "again", "--lake", lake]) == 2
    )
    assert "already" in capsys.readouterr().err
    assert main(["lake", "ls", "--lake", lake, "--format", "json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert [(r["robot"], r["run"], r["events"]) for r in listed] == [("r1", "robot", 812)]
    other = str(tmp_path / "other")
    assert main(["lake", "add", str(V1_LOG), "--robot", "bad/name", "--lake", other]) == 2
    assert "robot name 'bad/name'" in capsys.readouterr().err


PYARROW_EXAMPLE = re.search(r"```python\n(# pyarrow: one event type.*?)```", DOC.read_text(), re.S)


def test_the_documented_pyarrow_example_reads_one_type_with_all_its_columns(
    lake: TableLake, con: duckdb.DuckDBPyConnection
) -> None:
    assert PYARROW_EXAMPLE is not None, "docs/analytics.md lost its pyarrow example"
    code = PYARROW_EXAMPLE.group(1).replace('"out/lake"', repr(str(lake.root)))
    scope: dict[str, object] = {}
    exec(compile(code, str(DOC), "exec"), scope)
    detections = scope["detections"]
    expected = con.execute("SELECT count(*), count(DISTINCT run) FROM detection").fetchone()
    assert (detections.num_rows, len(set(detections.column("run").to_pylist()))) == expected  # type: ignore[attr-defined]
    names = set(detections.schema.names)  # type: ignore[attr-defined]
    assert {"mask_area", "position", "accepted", "robot", "date", "run"} <= names
