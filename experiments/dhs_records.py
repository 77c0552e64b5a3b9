"""What ``bench dhs`` runs and records: its experiment configs and agents by name, one job, one
query as its task scored it, one run (:mod:`objsearch.experiments.dhs`)."""

from __future__ import annotations

import statistics
from dataclasses import dataclass, field

#: Its experiment configs whose scenes we run (each names a ``scene_gen`` and the agents'
#: priors): the paper's small and large scenes, the large ones with noisier priors and with
#: coarse agent priors. The others repeat large_scenes' scenes for the learned models'
#: ablations (add_remove_objs, agent_no_priors, example, model_no_fuse) or need iGridson
#: (simulate_agents) or only draw images (save_images).
EXPERIMENTS = ("small_scenes", "large_scenes", "noisy_priors", "agent_ok_priors")
#: Every experiment config whose scenes can run here: also those that repeat large_scenes'.
RUNNABLE_EXPERIMENTS = (
    *EXPERIMENTS,
    "add_remove_objs",
    "agent_no_priors",
    "example",
    "model_no_fuse",
)
#: Its non-learned agents, by its names; its metrics module shows memorization as "Myopic",
#: upper_bound as "Oracle" (oracle_upper_bound also knows every position at a scene's start).
THEIR_AGENTS = (
    "random",
    "priors",
    "frequentist",
    "memorization",
    "bayesian",
    "upper_bound",
)
ALL_THEIR_AGENTS = (*THEIR_AGENTS, "oracle_upper_bound")
#: Our agent's name in tables.
OURS = "belief"
#: What our agent takes a furniture node's class to be (:class:`BeliefAgent`).
FURNITURE_KEYS = ("category", "label")
#: Display names (its ``memsearch.metrics.rename``).
DISPLAY = {
    "memorization": "myopic",
    "upper_bound": "oracle",
    "oracle_upper_bound": "oracle+start",
}
#: Its learned agents (SGM with its "NEP" GNNs), each ``sgm_<model>`` with its model config
#: ``configs/model/<model>.yaml``. The repository ships no weights: they run from a model trained
#: here (:mod:`objsearch.experiments.dhs_sgm`), on a CPU.
SGM_AGENTS = ("sgm_mlp", "sgm_gcn", "sgm_heat", "sgm_hgt", "sgm_han")


@dataclass(frozen=True, slots=True)
class Query:
    """One query of its find-object task as its loop scored it."""

    scene: int
    attempts: int
    found: bool
    cost: float
    #: Our agent only: the places it was shown in the query (``view_taken`` events).
    looks: int | None = None


@dataclass(frozen=True, slots=True)
class DhsJob:
    source: str
    experiment: str
    agent: str
    seed: int
    steps: int | None = None
    eps_per_scene: int | None = None
    #: Our agent's place classes (:data:`FURNITURE_KEYS`): its furniture category, or its label
    #: (the adapter before; kept for the A/B in docs/results-dhs.md).
    furniture_key: str = "category"
    #: Its learned agents only: its ``log_path`` where ``dhs_sgm train`` saved their weights
    #: (``<sgm_outputs>/<experiment>/models/<model>.pt``).
    sgm_outputs: str | None = None


@dataclass
class AgentRun:
    experiment: str
    agent: str
    seed: int
    max_attempts: int
    queries: list[Query] = field(default_factory=list)
    elapsed_s: float = 0.0
    #: Its code raised: the run stops there and its queries so far count (a run whose code
    #: raised on its first query has none, and no metrics: None).
    crash: str | None = None
    #: The process that ran it: :func:`run_dhs` gives every (agent, seed) a fresh one.
    pid: int = 0

    @property
    def mean_attempts(self) -> float | None:
        return statistics.fmean(q.attempts for q in self.queries) if self.queries else None

    @property
    def found(self) -> float | None:
        return sum(q.found for q in self.queries) / len(self.queries) if self.queries else None

    @property
    def mean_cost(self) -> float | None:
        return statistics.fmean(q.cost for q in self.queries) if self.queries else None

    def line(self) -> str:
        """What ``bench dhs`` prints when the run ends: its metrics, or that it has none."""
        crash = f"; its code raised: {self.crash}" if self.crash else ""
        name = f"{self.experiment} {self.agent} seed {self.seed}"
        if self.mean_attempts is None or self.found is None:
            return f"{name}: CRASHED before a query was answered ({self.elapsed_s} s){crash}"
        return (
            f"{name}: {self.mean_attempts:.3f} attempts, {self.found:.1%} found, "
            f"{len(self.queries)} queries ({self.elapsed_s} s){crash}"
        )
