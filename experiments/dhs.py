"""``objsearch bench dhs``: our belief inside the Dynamic House Simulator's find-object task.

The Dynamic House Simulator (DHS) of Kurenkov et al., "Modeling Dynamic Environments with Scene
Graph Memory" (ICML 2023), is the public repository ``andreykurenkov/modeling_env_dynamics``. It
is GPL-3.0 and is not part of objsearch: the user checks it out at :data:`PINNED_COMMIT` and
passes the folder (``--source`` or ``$OBJSEARCH_DHS_SOURCE``). :func:`verify_source` refuses a
checkout whose files differ from that commit's (:data:`PINNED_FILES`, SHA-256), so its dynamics,
task and agents are the published ones, unmodified. Nothing here patches or subclasses its code
(its learned agents run on the CPU with a re-uploaded text model lent while they run:
:mod:`objsearch.experiments.dhs_sgm`).

The loop of :func:`run_agent` is the find-object path of its ``memsearch.running.run`` (the
loop its ``scripts/eval.py`` runs per agent after ``random.seed(0)``), without what does not
touch the task or the random stream: the text featurizers (which load a spaCy or
sentence-transformers model from a hub), TensorBoard and the progress bar. Its agents are made
by its own ``make_agent``; ours enters at the agent seam, :class:`BeliefAgent`, which answers the
calls its ``FindObjTask.step`` and the loop make (``make_predictions``, ``receive_observation``,
``transition_to_new_scene``, ``step``) by folding our own events into
:class:`objsearch.agent.belief.PlaceBelief`. What the adapter maps (docs/results-dhs.md):

========================================  ==================================================
DHS                                       objsearch
========================================  ==================================================
a scene (house sampled by its sampler)    a home: a fresh belief (its agents also reset)
a furniture node                          a place (static instance): id = its ``unique_id``,
                                          class = its ``label``, room = its room's
                                          ``description``
an object node                            a target class d = its ``description`` (the
                                          identity its queries and its agents use)
its priors graph (the agents' type,       the seed Rel₀(d, furniture label) = the normalised
``detailed`` or ``coarse``)               priors edge furniture label -> object label, the
                                          same numbers its ``priors`` agent samples from
a query (``task.reset()``: the scene      one task and one episode (``task_started`` with
evolves one step, then an object is       scene = the query's index): objects may have moved
asked for)                                since the last query
an attempt (``receive_observation`` of    ``view_taken`` of that place, and a ``detection``
a furniture node)                         at it (support ``at``) of each object child kept by
                                          its observation model (each child dropped with
                                          probability 1 − ``observation_prob``, the draw its
                                          memory agents make)
a visited node (``ignore_nodes``)         a place looked at in this task: the belief of the
                                          target there is conditioned on the miss
the query ends (``agent.step()``)         ``task_ended``: the episode's sightings and misses
                                          become evidence (a target never seen: censored)
========================================  ==================================================

Our prediction is the unvisited furniture node with the highest belief (ties: the simulator's
node order); with no mass on any, a uniform random choice as its agents' fallback. The belief's
constants are the strategy ``ecost-belief``'s (``BELIEF``), not tuned to this simulator.

Its metric is its task's reward: the number of attempts until the object is found, capped at
``max_attempts`` + 1 when it is not found within ``max_attempts`` (10); lower is better. We also
report the share found and its accumulated travel cost (``acc_cost``, its ``get_cost_between_nodes``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import io
import os
import random
import time
import traceback
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from objsearch.experiments.dhs_adapter import (
    PINNED_COMMIT,
    PINNED_FILES,
    SOURCE_ENV,
    BeliefAgent,
    RecordEvent,
    _missing_dependency,
    _their_code,
    load_config,
    make_belief_agent,
    sighting,
    verify_source,
)
from objsearch.experiments.dhs_bound import BOUND, BOUND_AGENTS, BoundAgent, bound_agent
from objsearch.experiments.dhs_records import (
    ALL_THEIR_AGENTS,
    DISPLAY,
    EXPERIMENTS,
    FURNITURE_KEYS,
    OURS,
    RUNNABLE_EXPERIMENTS,
    SGM_AGENTS,
    THEIR_AGENTS,
    AgentRun,
    DhsJob,
    Query,
)
from objsearch.experiments.dhs_report import paired_ci, render, summarise

__all__ = [
    "ALL_THEIR_AGENTS",
    "BOUND",
    "BOUND_AGENTS",
    "DISPLAY",
    "EXPERIMENTS",
    "FURNITURE_KEYS",
    "HASH_SEED",
    "OURS",
    "PINNED_COMMIT",
    "PINNED_FILES",
    "RUNNABLE_EXPERIMENTS",
    "SGM_AGENTS",
    "SOURCE_ENV",
    "THEIR_AGENTS",
    "AgentRun",
    "BeliefAgent",
    "BoundAgent",
    "DhsJob",
    "Query",
    "RecordEvent",
    "Watch",
    "load_config",
    "paired_ci",
    "render",
    "run_agent",
    "run_dhs",
    "sighting",
    "summarise",
    "verify_source",
]


def _make_agent(
    name: str, cfg: Any, sampler: Any, evolver: Any, furniture_key: str = "category"
) -> Any:
    from memsearch.agents import make_agent
    from memsearch.tasks import TaskType

    if name in BOUND_AGENTS:
        return bound_agent(name, sampler, evolver, float(cfg.agents.observation_prob))
    if name in SGM_AGENTS:
        from objsearch.experiments.dhs_sgm import make_sgm_agent

        return make_sgm_agent(cfg, name, sampler, evolver)
    if name != OURS:
        return make_agent(
            cfg.agents,
            name,
            TaskType.FIND_OBJECT,
            None,
            None,
            sampler,
            evolver,
            False,
            None,
        )
    return make_belief_agent(cfg, furniture_key)


#: Called after each query its task scored, before the scene evolves: (its task, the agent, the
#: query's object node, the query as scored, its task's ``info``). For diagnostics
#: (``objsearch.experiments.dhs_changes``); it must not draw from ``random``.
Watch = Callable[[Any, Any, Any, "Query", Mapping[str, Any]], None]


def run_agent(job: DhsJob, watch: Watch | None = None) -> AgentRun:
    """One agent on one experiment config and seed: its eval loop (``random.seed(seed)``, then
    ``run`` with the find-object task), with our agent made by us and its by ``make_agent``."""
    root = Path(job.source)
    # Its config keeps its task's num_steps (its learned agents' featurizers scale by it, as in
    # their training); a shorter run only stops its loop sooner.
    overrides = []
    if job.eps_per_scene is not None:
        overrides.append(f"task.eps_per_scene={job.eps_per_scene}")
    learned: contextlib.AbstractContextManager[None] = contextlib.nullcontext()
    if job.agent in SGM_AGENTS:
        from objsearch.experiments.dhs_sgm import cpu_and_text_model, sgm_overrides

        overrides.extend(sgm_overrides(job.agent, job.sgm_outputs))
        learned = cpu_and_text_model()
    cfg = load_config(root, job.experiment, overrides)
    started = time.perf_counter()
    with _their_code(root), learned:
        try:
            # gym 0.26 prints a notice that it is unmaintained when imported.
            with contextlib.redirect_stderr(io.StringIO()):
                scene_mod = importlib.import_module("memsearch.scene")
                tasks_mod = importlib.import_module("memsearch.tasks")
                importlib.import_module("memsearch.agents")
        except ModuleNotFoundError as error:
            raise _missing_dependency(error) from None
        find_object = tasks_mod.TaskType.FIND_OBJECT
        random.seed(job.seed)  # its eval_agent: random.seed(0) before run()
        sampler, evolver = scene_mod.make_scene_sampler_and_evolver(cfg.scene_gen)
        agent = _make_agent(job.agent, cfg, sampler, evolver, job.furniture_key)
        task = tasks_mod.make_task(
            sampler, evolver, find_object, eps_per_scene=cfg.task.eps_per_scene
        )
        out = AgentRun(
            job.experiment,
            job.agent,
            job.seed,
            int(cfg.task.max_attempts),
            pid=os.getpid(),
        )
        scene_num, current_scene, query_nodes = 0, None, None
        for _ in range(job.steps if job.steps is not None else int(cfg.task.num_steps)):
            try:
                if task.scene is None or current_scene != task.scene:
                    if current_scene is None:
                        query_nodes = task.reset()
                    scene_num += 1
                    current_scene = task.scene
                    agent.transition_to_new_scene(current_scene)
                prediction = agent.make_predictions(
                    find_object, current_scene, query_nodes, top_k=cfg.task.top_k
                )
                obs, score, done, info = task.step(
                    prediction,
                    agent=agent,
                    current_scene=current_scene,
                    query_nodes=query_nodes,
                    max_attempts=cfg.task.max_attempts,
                    top_k=cfg.task.top_k,
                )
                agent.receive_observation(obs)
                found = int(score) <= out.max_attempts
                out.queries.append(Query(scene_num, int(score), found, float(info["acc_cost"])))
                if watch is not None:
                    watch(task, agent, query_nodes, out.queries[-1], info)
                if done:
                    query_nodes = task.reset()
                    agent.step()
                if isinstance(agent, BeliefAgent):
                    out.queries[-1] = dataclasses.replace(out.queries[-1], looks=agent.last_looks)
            except Exception as error:  # boundary: its code's crash ends the run (ours re-raised)
                if not _raised_by_their_code(error):
                    raise
                out.crash = (
                    f"{type(error).__name__}: {error} in its code at query "
                    f"{len(out.queries) + 1}, scene {scene_num}"
                )
                break
    out.elapsed_s = round(time.perf_counter() - started, 2)
    return out


def _raised_by_their_code(error: BaseException) -> bool:
    """True unless, below the frame that caught it, a frame of ours (but the 3.8 draw it lends
    its code) is on the way to the raise: our agent's bugs are not its crashes."""
    ours = Path(__file__).resolve().parents[1]
    for frame in traceback.extract_tb(error.__traceback__)[1:]:
        path = Path(frame.filename).resolve()
        if path.is_relative_to(ours) and frame.name != "_choices_py38":
            return False
    return True


#: ``PYTHONHASHSEED`` of the processes that run the simulator.
HASH_SEED = "0"


@contextlib.contextmanager
def _environ(**values: str) -> Iterator[None]:
    """``os.environ`` with ``values`` set while the block runs (the processes it spawns inherit
    them), as it was afterwards."""
    before = {name: os.environ.get(name) for name in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for name, value in before.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def run_dhs(
    source: Path,
    *,
    experiments: Sequence[str],
    agents: Sequence[str],
    seeds: Sequence[int],
    steps: int | None = None,
    eps_per_scene: int | None = None,
    workers: int = 1,
    progress: Callable[[AgentRun], None] | None = None,
    sgm_outputs: Path | None = None,
) -> dict[str, Any]:
    """Every (experiment, agent, seed), ``workers`` at a time, each in a fresh process, summarised.

    A fresh process per run: its nodes hash by identity and its ids come from ``uuid4``, so a
    run in a process that ran another before it meets its sets in another order (measured: a
    seed moved by 0.1-0.33 attempts with what ran before it). Each process is spawned with
    ``PYTHONHASHSEED=0`` (:data:`HASH_SEED`), so its string sets iterate alike too.
    """
    # Seed by seed, its agents beside ours: the pairs finish together.
    jobs = [
        DhsJob(
            str(source),
            e,
            a,
            s,
            steps,
            eps_per_scene,
            sgm_outputs=str(sgm_outputs) if sgm_outputs and a in SGM_AGENTS else None,
        )
        for e in experiments
        for s in seeds
        for a in agents
    ]
    runs: list[AgentRun] = []
    started = time.perf_counter()
    import concurrent.futures as cf
    import multiprocessing

    context = multiprocessing.get_context("spawn")
    with (
        _environ(PYTHONHASHSEED=HASH_SEED),
        cf.ProcessPoolExecutor(
            max_workers=max(1, min(workers, len(jobs))),
            mp_context=context,
            max_tasks_per_child=1,
        ) as pool,
    ):
        for run in pool.map(run_agent, jobs):
            runs.append(run)
            if progress:
                progress(run)
    summary = summarise(runs)
    summary["elapsed_s"] = round(time.perf_counter() - started, 1)
    summary["seeds"] = list(seeds)
    summary["steps"] = steps
    summary["eps_per_scene"] = eps_per_scene
    return summary
