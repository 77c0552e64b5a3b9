"""Where the attempts go in the Dynamic House Simulator: each query split by what happened to
its object since the agent last had it in view.

``python -m objsearch.experiments.dhs_changes --experiment large_scenes --agents belief,bayesian
--seeds 0,1 --steps 2200`` runs each (agent, seed) in a fresh process, as ``bench dhs`` does, and
prints per agent and kind of query the share of queries, the mean attempts and the share found,
then each agent's mean attempts per seed and, seed by seed, the first agent minus each other
(95 % t interval). ``belief@label`` is our agent with the place classes it had before (the
furniture label, :data:`objsearch.experiments.dhs.FURNITURE_KEYS`), for the A/B.

Kinds, from the simulator's scene graph at the query (the task does not change the scene while
the agent searches) against where the object was when a place the agent tried last held it
("in view": before its observation model drops a child, so what the agent could have seen):

- ``never in view, added``: its object node appeared in the scene after the scene's first query
  (its evolver adds objects in large scenes);
- ``never in view``: there since the scene's first query, never in a place the agent tried;
- ``replaced``: in view before, but as another object node with the same description (the one
  seen was removed and one alike added, or two alike are in the scene: its descriptions repeat,
  and this kind is 9-11 % of small scenes' queries, where nothing is added or removed); the
  description is the identity its task asks for;
- ``moved``: the same node, now at another piece of furniture;
- ``stayed``: the same node at the same furniture.

Each kind also counts the queries whose object its evolver moved in the step just before the
query (``moved this step``): its task asks for such an object half of the time
(``pct_query_moved_object`` 0.5).
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import multiprocessing
import statistics
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from objsearch.experiments.dhs import (
    HASH_SEED,
    DhsJob,
    Query,
    _environ,
    paired_ci,
    run_agent,
    verify_source,
)

KINDS = ("stayed", "moved", "replaced", "never in view", "never in view, added")


@dataclass(frozen=True, slots=True)
class Scored:
    """One query: its kind, whether its object moved in the step before it, and its score."""

    kind: str
    moved_this_step: bool
    attempts: int
    found: bool


@dataclass
class _Tracker:
    """What the agent had in view, per scene (a new scene forgets it, as the agents do)."""

    scene: Any = None
    #: description -> (object node id, furniture id) when a tried place last held it.
    in_view: dict[str, tuple[str, str]] = field(default_factory=dict)
    #: Object node ids present at the scene's first query.
    initial: set[str] = field(default_factory=set)
    moved_seen: int = 0
    scored: list[Scored] = field(default_factory=list)

    def __call__(
        self, task: Any, agent: Any, target: Any, query: Query, info: Mapping[str, Any]
    ) -> None:
        from memsearch.graphs import NodeType

        graph = task.scene.scene_graph
        evolver = task.scene_evolver
        if task.scene is not self.scene:
            self.scene, self.in_view = task.scene, {}
            self.initial = {n.unique_id for n in graph.get_nodes_with_type(NodeType.OBJECT)}
        # Its evolver appends what it moves; since the last query: the step before this one.
        moved_now = evolver.moved_objects[self.moved_seen :]
        self.moved_seen = len(evolver.moved_objects)
        where = target.get_parent_node().unique_id
        seen = self.in_view.get(target.description)
        if seen is None:
            kind = "never in view" if target.unique_id in self.initial else "never in view, added"
        elif seen[0] != target.unique_id:
            kind = "replaced"
        elif seen[1] != where:
            kind = "moved"
        else:
            kind = "stayed"
        self.scored.append(
            Scored(kind, any(n is target for n in moved_now), query.attempts, query.found)
        )
        for place in info["visited_nodes"]:
            for child in place.get_children_nodes():
                if child.type == NodeType.OBJECT:
                    self.in_view[child.description] = (child.unique_id, place.unique_id)


def score_run(job: DhsJob) -> tuple[DhsJob, list[Scored]]:
    """One (agent, seed) with every query scored and classified (in the process that runs it)."""
    tracker = _Tracker()
    run_agent(job, watch=tracker)
    return job, tracker.scored


def table(scored: Mapping[str, Sequence[Scored]]) -> str:
    """Per agent and kind: share of queries, mean attempts, share found; then moved this step."""
    lines = [
        f"  {'agent':<10} {'kind':<22} {'queries':>8} {'share':>6} {'attempts':>9} {'found':>6}"
    ]
    for agent, rows in scored.items():
        groups: list[tuple[str, list[Scored]]] = [
            (k, [r for r in rows if r.kind == k]) for k in KINDS
        ]
        groups += [
            ("moved this step", [r for r in rows if r.moved_this_step]),
            ("not moved this step", [r for r in rows if not r.moved_this_step]),
            ("all", list(rows)),
        ]
        for kind, group in groups:
            if not group:
                continue
            attempts = statistics.fmean(r.attempts for r in group)
            found = sum(r.found for r in group) / len(group)
            lines.append(
                f"  {agent:<10} {kind:<22} {len(group):>8} {len(group) / len(rows):>6.1%} "
                f"{attempts:>9.3f} {found:>6.1%}"
            )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m objsearch.experiments.dhs_changes")
    parser.add_argument("--source", help="the simulator's checkout ($OBJSEARCH_DHS_SOURCE)")
    parser.add_argument("--experiment", default="large_scenes")
    parser.add_argument("--agents", default="belief,bayesian")
    parser.add_argument("--seeds", default="0,1")
    parser.add_argument("--steps", type=int, default=2200)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    source = verify_source(args.source)
    agents = args.agents.split(",")
    seeds = [int(s) for s in args.seeds.split(",")]
    jobs = [
        job(str(Path(source)), args.experiment, a, s, args.steps) for s in seeds for a in agents
    ]
    scored: dict[str, list[Scored]] = {a: [] for a in agents}
    per_seed: dict[str, dict[int, float]] = {a: {} for a in agents}
    with (
        _environ(PYTHONHASHSEED=HASH_SEED),
        cf.ProcessPoolExecutor(
            max_workers=args.workers,
            mp_context=multiprocessing.get_context("spawn"),
            max_tasks_per_child=1,
        ) as pool,
    ):
        for (name, seed), (_, rows) in zip(
            ((a, s) for s in seeds for a in agents), pool.map(score_run, jobs), strict=True
        ):
            scored[name] += rows
            per_seed[name][seed] = statistics.fmean(r.attempts for r in rows)
            print(f"  {name} seed {seed}: {per_seed[name][seed]:.3f} attempts", flush=True)
    print(f"{args.experiment}, seeds {args.seeds}, {args.steps} queries per run")
    print(table(scored))
    print(paired(per_seed))
    return 0


def job(source: str, experiment: str, name: str, seed: int, steps: int) -> DhsJob:
    """The run of ``name``: an agent, or ``belief@KEY`` (our agent with place classes KEY)."""
    agent, _, key = name.partition("@")
    return DhsJob(source, experiment, agent, seed, steps, furniture_key=key or "category")


def paired(per_seed: Mapping[str, Mapping[int, float]]) -> str:
    """Mean attempts per seed, and the first agent minus each other, seed by seed."""
    names = list(per_seed)
    lines = ["  mean attempts per seed:"]
    for name in names:
        values = " ".join(f"{v:.3f}" for _, v in sorted(per_seed[name].items()))
        lines.append(f"    {name:<14} {values}")
    first = names[0]
    for other in names[1:]:
        seeds = sorted(per_seed[first].keys() & per_seed[other].keys())
        diffs = [per_seed[first][s] - per_seed[other][s] for s in seeds]
        ci = paired_ci(diffs)
        interval = "" if ci is None else f" [{ci[0]:+.3f}, {ci[1]:+.3f}]"
        lines.append(
            f"  {first} − {other}: {statistics.fmean(diffs):+.3f}{interval} (95 % t, "
            f"{len(seeds)} seeds: {' '.join(f'{d:+.3f}' for d in diffs)})"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
