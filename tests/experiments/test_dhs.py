"""The Dynamic House Simulator adapter (objsearch.experiments.dhs).

The simulator is not part of objsearch (GPL-3.0, public repository): the tests that run it need
a checkout of the pinned commit in ``$OBJSEARCH_DHS_SOURCE`` and its dependencies (``make dhs``),
and are skipped without them. The pinning, the Python 3.8 draw and the CLI's errors are tested
everywhere.
"""

from __future__ import annotations

import importlib.util
import os
import random
from pathlib import Path

import pytest

from devtools.cli_process import run_cli
from objsearch.agent.belief import Place, PlaceBelief
from objsearch.agent.errors import ObjsearchError
from objsearch.experiments import dhs, dhs_adapter, dhs_report


def test_a_checkout_that_differs_from_the_pinned_commit_is_refused(tmp_path: Path) -> None:
    (tmp_path / "memsearch").mkdir()
    (tmp_path / "memsearch" / "agents.py").write_text("# not theirs\n")
    with pytest.raises(ObjsearchError, match=r"not modeling_env_dynamics at commit 74e5f9d72246"):
        dhs.verify_source(tmp_path)
    try:
        dhs.verify_source(tmp_path)
    except ObjsearchError as error:
        assert "changed memsearch/agents.py" in str(error)
        assert "missing configs/agents/all.yaml" in str(error)


def test_without_a_checkout_the_error_says_where_to_put_it(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.delenv(dhs.SOURCE_ENV, raising=False)
    with pytest.raises(ObjsearchError, match=r"--source DIR or set \$OBJSEARCH_DHS_SOURCE"):
        dhs.verify_source(None)
    with pytest.raises(ObjsearchError, match="no such folder"):
        dhs.verify_source(tmp_path / "absent")


def test_the_cli_refuses_an_unpinned_checkout_with_a_clear_error(tmp_path: Path) -> None:
    done = run_cli("bench", "dhs", "--source", str(tmp_path))
    assert done.returncode == 2
    assert "objsearch: error:" in done.stderr and "Traceback" not in done.stderr
    assert "missing memsearch/" in done.stderr or "missing configs/" in done.stderr


def test_the_py38_draw_picks_the_last_option_of_all_zero_weights_and_costs_one_random() -> None:
    options = ["a", "b", "c"]
    random.seed(5)
    picked = dhs_adapter._choices_py38(options, weights=[0.0, 0.0, 0.0])
    after = random.random()
    random.seed(5)
    random.random()
    assert picked == ["c"] and random.random() == after


def test_the_py38_draw_is_pythons_own_when_the_weights_sum_above_zero() -> None:
    options, weights = ["a", "b", "c"], [0.2, 0.0, 0.8]
    random.seed(11)
    ours = [dhs_adapter._choices_py38(options, weights=weights)[0] for _ in range(50)]
    random.seed(11)
    theirs = [random.choices(options, weights=weights)[0] for _ in range(50)]
    assert ours == theirs


def test_only_an_error_raised_in_their_code_ends_a_run_quietly(tmp_path: Path) -> None:
    # A module outside objsearch stands for the simulator's code.
    theirs = tmp_path / "theirs.py"
    theirs.write_text("def reset(weights):\n    return weights[-1]\n")
    spec = importlib.util.spec_from_file_location("theirs", theirs)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    with pytest.raises(IndexError) as theirs_raised:
        module.reset([])
    assert dhs._raised_by_their_code(theirs_raised.value)
    # Our agent's bug is not theirs: it propagates.
    with pytest.raises(ValueError) as ours_raised:
        PlaceBelief(prior_strength=0.0)
    assert not dhs._raised_by_their_code(ours_raised.value)


def _source() -> Path:
    source = os.environ.get(dhs.SOURCE_ENV)
    if not source:
        pytest.skip(f"no checkout of the simulator (${dhs.SOURCE_ENV})")
    for module in ("hydra", "gym", "torch_geometric", "spacy", "sentence_transformers"):
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"the simulator's dependency {module} is not installed (make dhs)")
    return dhs.verify_source(source)


@pytest.mark.slow
def test_its_agents_and_ours_run_in_its_task_by_its_rules() -> None:
    source = _source()
    # One small scene (3 rooms, 6 pieces of furniture each), 60 queries: a few seconds a run
    # (importing its code, which loads torch_geometric and transformers, takes longer).
    runs = {
        agent: dhs.run_agent(dhs.DhsJob(str(source), "small_scenes", agent, 0, 60, 60))
        for agent in ("random", "upper_bound", dhs.OURS)
    }
    for run in runs.values():
        assert len(run.queries) == 60 and run.max_attempts == 10
        assert {q.scene for q in run.queries} == {1}
        for q in run.queries:
            assert 1 <= q.attempts <= run.max_attempts + 1
            assert q.found == (q.attempts <= run.max_attempts)
    # Its task shows our agent each place it tries, then the loop shows the last one again:
    # a found object costs attempts + 1 looks, one not found within 10 costs 11 (its 11th
    # prediction, never tried).
    for q in runs[dhs.OURS].queries:
        assert q.looks == q.attempts + q.found
    # Its oracle knows the true move probabilities: fewer attempts than its random agent.
    upper, chance, ours = (runs[a].mean_attempts for a in ("upper_bound", "random", dhs.OURS))
    assert upper is not None and chance is not None and ours is not None
    assert upper < chance and ours < chance
    summary = dhs.summarise(list(runs.values()))
    rows = summary["experiments"]["small_scenes"]["agents"]
    assert rows[dhs.OURS]["attempts_per_seed"] == [round(ours, 4)]
    assert "small_scenes" in dhs.render(summary)


def test_the_targets_read_the_gap_from_the_better_baseline_to_the_better_oracle() -> None:
    def rows(**attempts: float) -> dict[str, dict[str, float]]:
        return {agent: {"attempts": value} for agent, value in attempts.items()}

    half = dhs_report._targets(
        rows(belief=2.0, frequentist=3.0, memorization=4.0, upper_bound=1.0, oracle_upper_bound=2.5)
    )
    assert half is not None
    assert half["better_baseline"] == "frequentist" and half["oracle"] == "upper_bound"
    assert half["gap_closed"] == pytest.approx(0.5) and half["half_gap_closed"]
    # An oracle no better than the better baseline leaves no gap: said so, not a ratio.
    none = dhs_report._targets(rows(belief=2.0, frequentist=2.4, memorization=3.0, upper_bound=3.5))
    assert none is not None and none["gap_closed"] is None and none["beats_oracle"]
    assert "no gap to close" in dhs_report._verdict(none)
    assert dhs_report._targets(rows(belief=2.0, frequentist=2.4)) is None  # no oracle ran


def _run(agent: str, seed: int, attempts: list[int], crash: str | None = None) -> dhs.AgentRun:
    run = dhs.AgentRun("agent_ok_priors", agent, seed, max_attempts=10, crash=crash)
    run.queries = [dhs.Query(1, a, a <= 10, 2.0 * a) for a in attempts]
    return run


def test_a_run_whose_code_raised_on_its_first_query_is_a_crash_not_an_error() -> None:
    # As `bench dhs --experiments agent_ok_priors --agents bayesian`: its code raises on the first
    # query, so the run has none (fmean of nothing raised StatisticsError, exit 1).
    raised = "ValueError: probabilities do not sum to 1 in its code at query 1, scene 1"
    crashed = _run("bayesian", 0, [], crash=raised)
    assert crashed.mean_attempts is None and crashed.found is None and crashed.mean_cost is None
    line = crashed.line()
    assert "CRASHED before a query was answered" in line and raised in line
    runs = [
        crashed,
        _run("bayesian", 1, [1, 3]),
        _run("random", 0, [], crash=raised),
        _run(dhs.OURS, 0, [1, 2]),
        _run("frequentist", 0, [2, 4]),
        _run("memorization", 0, [3, 5]),
        _run("upper_bound", 0, [1, 1]),
    ]
    summary = dhs.summarise(runs)
    rows = summary["experiments"]["agent_ok_priors"]["agents"]
    # The seed that answered counts; the one that crashed is named, not averaged as a number.
    assert rows["bayesian"]["attempts"] == 2.0 and rows["bayesian"]["attempts_per_seed"] == [
        None,
        2.0,
    ]
    assert rows["bayesian"]["crashes"] == [f"seed 0: {raised}"]
    assert rows["random"]["attempts"] is None and rows["random"]["found"] is None
    assert summary["experiments"]["agent_ok_priors"]["targets"]["attempts"]["ours"] == 1.5
    text = dhs.render(summary)
    random_row = next(line for line in text.splitlines() if line.split()[:1] == ["random"])
    assert random_row.split()[1] == "crashed"
    assert "runs its code ended by raising" in text and raised in text
    # Every agent crashed at once: no targets, still a table.
    alone = dhs.summarise([_run("bayesian", 0, [], crash=raised)])
    assert alone["experiments"]["agent_ok_priors"]["targets"] is None
    assert "crashed" in dhs.render(alone)


def test_paired_differences_are_per_seed_with_a_t_interval() -> None:
    # Ours − its bayesian per seed: -0.2, -0.2, -0.3 (mean -0.233, sd 0.0577; t(2) 4.303).
    runs = [
        _run(dhs.OURS, 0, [2] * 10),
        _run(dhs.OURS, 1, [3] * 10),
        _run(dhs.OURS, 2, [1] * 10),
        _run("bayesian", 0, [2] * 8 + [3] * 2),
        _run("bayesian", 1, [3] * 8 + [4] * 2),
        _run("bayesian", 2, [1] * 7 + [2] * 3),
        _run("random", 0, [9, 9]),
    ]
    summary = dhs.summarise(runs)
    paired = summary["experiments"]["agent_ok_priors"]["paired"]
    bayes = paired["bayesian"]
    assert bayes["seeds"] == [0, 1, 2]
    assert bayes["diffs"] == pytest.approx([-0.2, -0.2, -0.3])
    mean, half = -0.7 / 3, 4.303 * (0.01 / 3) ** 0.5 / 3**0.5
    assert bayes["mean"] == pytest.approx(mean, abs=1e-4)
    assert bayes["ci95"] == pytest.approx([mean - half, mean + half], abs=1e-4)
    # One seed in common: a difference, no interval.
    assert paired["random"]["diffs"] == pytest.approx([-7.0]) and paired["random"]["ci95"] is None
    text = dhs.render(summary)
    assert "paired by seed, ours − its" in text
    line = next(x for x in text.splitlines() if x.split()[:1] == ["bayesian"] and "[" in x)
    assert "ours ahead" in line and "3 seeds" in line
    assert "one seed: no interval" in text


def test_an_interval_that_straddles_zero_says_so() -> None:
    assert dhs.paired_ci([0.1]) is None
    lo, hi = dhs.paired_ci([0.1, -0.1, 0.05])  # type: ignore[misc]
    assert lo < 0 < hi
    lines = dhs_report._paired_lines(
        {
            "bayesian": {
                "seeds": [0, 1, 2],
                "diffs": [0.1, -0.1, 0.05],
                "mean": 0.0167,
                "ci95": [lo, hi],
            }
        }
    )
    assert "CI includes 0" in lines[1]


@pytest.mark.slow
def test_every_agent_and_seed_runs_in_a_fresh_process() -> None:
    source = _source()
    summary_runs: list[dhs.AgentRun] = []
    dhs.run_dhs(
        source,
        experiments=["small_scenes"],
        agents=["random", dhs.OURS],
        seeds=[0, 1],
        steps=3,
        workers=1,
        progress=summary_runs.append,
    )
    pids = [r.pid for r in summary_runs]
    assert len(pids) == 4 and len(set(pids)) == 4 and os.getpid() not in pids


def test_our_rel0_is_the_edge_its_bayesian_reads_per_furniture_category() -> None:
    source = _source()
    with dhs_adapter._their_code(source):
        from memsearch.agents import BayesianAgent
        from memsearch.graphs import NodeType, load_priors_graph
        from memsearch.tasks import TaskType

        graph = load_priors_graph("detailed")
        for node in graph.nodes:
            node.normalize_edges_to_me()
        agent = dhs.BeliefAgent(graph, 0.75, prior_strength=1.0, half_life_scenes=3.0)
        furniture = graph.get_nodes_with_type(NodeType.FURNITURE)
        for node in furniture:
            agent.belief.places[node.category] = Place(node.category, node.category, "room")
        bayesian = BayesianAgent(graph, TaskType.FIND_OBJECT, 0.75, 0.05)
        differ = 0
        for label in ("mug", "apple", "smartphone", "book"):
            obj = graph.get_nodes_with_label(label)[0]
            rel = agent._rel0(label)
            bayesian.beta_distributions = {obj.description: {}}
            by_label: dict[str, set[float]] = {}
            for node in furniture:
                bayesian.init_dist_for_edge(obj, node)
                dist = bayesian.beta_distributions[obj.description][node]
                theirs = 0.0 if dist is None else float(dist.get_mean())
                assert rel.get(node.category, 0.0) == pytest.approx(theirs, abs=1e-9), node.category
                by_label.setdefault(node.label, set()).add(round(theirs, 9))
            differ += sum(len(v) > 1 for v in by_label.values())
        # Categories of one label carry different edges: a label-keyed prior merged them.
        assert differ > 0
        labelled = dhs.BeliefAgent(
            graph, 0.75, prior_strength=1.0, half_life_scenes=3.0, furniture_key="label"
        )
        for node in furniture:
            labelled.belief.places[node.label] = Place(node.label, node.label, "room")
        assert set(labelled._rel0("mug")) <= {n.label for n in furniture}


def test_with_its_coarse_priors_our_categories_find_their_roomless_category() -> None:
    # agent_ok_priors gives the agents its coarse graph, whose categories carry no room
    # (arm_chair, not arm_chair-bedroom): without the fallback every Rel₀ was 0 there.
    source = _source()
    with dhs_adapter._their_code(source):
        from memsearch.graphs import NodeType, load_priors_graph

        detailed, coarse = load_priors_graph("detailed"), load_priors_graph("coarse")
        for node in coarse.nodes:
            node.normalize_edges_to_me()
        agent = dhs.BeliefAgent(coarse, 0.75, prior_strength=1.0, half_life_scenes=3.0)
        categories = {n.category for n in detailed.get_nodes_with_type(NodeType.FURNITURE)}
        for category in categories:
            agent.belief.places[category] = Place(category, category, "room")
        rel = agent._rel0("mug")
        assert rel and set(rel) <= categories
        roomless = coarse.get_node_with_category("arm_chair")
        mug = coarse.get_nodes_with_label("mug")
        edges = [e.prob for o in mug for e in [roomless.get_edge_to(o)] if e is not None]
        if edges and max(edges) > 0:
            assert rel["arm_chair-bedroom"] == pytest.approx(min(1.0, max(edges)))
