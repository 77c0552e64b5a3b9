"""The analytics views: the closed-form scene graph equals the fold; the documented queries run."""

from __future__ import annotations

import json
import re
from pathlib import Path

import duckdb
import pytest
from objsearch.agent.scene_graph import SceneGraphProjection
from objsearch.events import fold, read_log
from objsearch.events.lake import Lake
from objsearch.replay.analytics import open_analytics

from objsearch.cli import main

DOC = Path(__file__).resolve().parents[2] / "docs" / "analytics.md"
QUESTIONS = re.findall(r"### (\d+)\. [^\n]*\n.*?```sql\n(.*?)```", DOC.read_text(), re.S)


@pytest.fixture(scope="module")
def con(lake: Lake) -> duckdb.DuckDBPyConnection:
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
    events = list(read_log(logs[run]))
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
    events = list(read_log(logs["robot"]))
    ended = [e for e in events if e.type == "task_ended"][5]
    last_at_time = max(e.seq for e in events if e.time_ns <= ended.time_ns)
    by_time = con.execute(
        "SELECT dynamic, static, rel FROM scene_graph_at_time(?) WHERE run = 'robot'",
        [ended.time_ns],
    ).fetchall()
    assert {(d, s): r for d, s, r in by_time} == _graph_sql(con, "robot", last_at_time)


def test_searches_agree_with_the_log(con: duckdb.DuckDBPyConnection, logs: dict[str, Path]) -> None:
    ended = [e for e in read_log(logs["targets"]) if e.type == "task_ended"]
    rows = con.execute(
        "SELECT task_id, target, success, path_length, method, update_mode FROM searches "
        "WHERE run = 'targets' ORDER BY task_index"
    ).fetchall()
    assert [(r[0], r[1], r[2], r[3]) for r in rows] == [
        (e.task_id, e.payload["target"], e.payload["success"], e.payload["path_length"])
        for e in ended
    ]
    assert {(r[4], r[5]) for r in rows} == {("rvp", "targets")}
    walked = con.execute(
        "SELECT max(abs(s.path_length - m.walked)) FROM searches s JOIN (SELECT run, task_id, "
        "sum(metres) AS walked FROM moved GROUP BY ALL) m USING (run, task_id)"
    ).fetchone()
    assert walked is not None and walked[0] < 1e-3


def test_plans_keep_the_chosen_order(con: duckdb.DuckDBPyConnection, logs: dict[str, Path]) -> None:
    plans = [e for e in read_log(logs["robot"]) if e.type == "plan_computed"]
    rows = con.execute(
        "SELECT seq, chosen_order, first_choice, candidates FROM plans WHERE run = 'robot' "
        "ORDER BY seq"
    ).fetchall()
    assert [(r[0], r[1], r[3]) for r in rows] == [
        (e.seq, list(e.payload["order"]), len(e.payload["candidates"])) for e in plans
    ]
    assert all(r[2] == (r[1][0] if r[1] else None) for r in rows)


# --- the command line ----------------------------------------------------------------------------


def test_query_formats(lake: Lake, capsys: pytest.CaptureFixture[str]) -> None:
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
    lake: Lake, tmp_path: Path, capsys: pytest.CaptureFixture[str]
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
    assert (
        main(["lake", "add", str(V1_LOG), "--robot", "r1", "--run", "again", "--lake", lake]) == 0
    )
    capsys.readouterr()
    assert main(["lake", "ls", "--lake", lake, "--format", "json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert [(r["robot"], r["run"], r["events"]) for r in listed] == [
        ("r1", "again", 812),
        ("r1", "robot", 812),
    ]
    assert main(["lake", "add", str(V1_LOG), "--robot", "bad/name", "--lake", lake]) == 2
    assert "robot name 'bad/name'" in capsys.readouterr().err
