"""Search strategies by name, and the run spec that records one in the log.

A strategy is a relation model (the fold of the log into Rel) and a stop planner, plus the room
order of its method. The paper's three methods (SDP, RVP, WPL) use Eq. 4 and their own planners.
Ours swap one seam each, never forking the policy: ``wpl-neg`` and ``wpl-neg-decay`` fold the same
log into a Beta posterior (negative evidence, decay toward the prior); ``epl`` orders stops by
expected path length; ``epl-neg-decay`` combines both.

``run_started`` records the whole :class:`RunSpec` — the strategy's name, its relation model *with
its parameters*, its planner, α, the update mode, the support radius, the schedule — and
:meth:`RunSpec.relation_model` / :meth:`RunSpec.stop_planner` / :meth:`RunSpec.config` are the one
place anything (the agent, replay, audit, the live view, the report, the lake) turns a log's spec
into the objects that fold and plan. Nothing reads a strategy's parameters from today's code when
the log has them.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any, Final, cast

from objsearch.agent.catalogue import (
    PlannerName,
    RelationModelName,
    RelationsSpec,
    RunStarted,
    decode_payload,
    encode,
)
from objsearch.agent.datapaths import DATA_ENV, data_key
from objsearch.agent.detector_model import PerceptionModel
from objsearch.agent.errors import ObjsearchError
from objsearch.agent.home import Home
from objsearch.agent.planner import (
    ExpectedPathPlanner,
    RelationOrderPlanner,
    StopPlanner,
    WplPlanner,
)
from objsearch.agent.policy import Method, SearchConfig
from objsearch.agent.relations import BetaRelations, RelationModel
from objsearch.agent.scene_graph import SceneGraphProjection, UpdateMode
from objsearch.agent.upcasters import STEPS
from objsearch.events.errors import InvalidEventError

#: Pseudo-observations of the Visual Genome prior in the Beta model. Fixed a priori (a weak prior
#: worth two searches), not tuned on any home.
PRIOR_STRENGTH = 2.0
#: Half-life of evidence, in tasks: 64 is one scene of the long-term protocol (8 targets × 8
#: starts). Fixed a priori, not tuned.
HALF_LIFE_TASKS = 64.0
DEFAULT_ALPHA = 10.0
DEFAULT_SUPPORT_RADIUS = 0.5

#: The memory model's recent evidence: half-life 8 tasks (one target's eight searches of a scene)
#: and weight 10 against long-run counts. Fixed a priori (docs/results.md), not tuned.
MEMORY_HALF_LIFE_TASKS = 8.0
MEMORY_RECENT_WEIGHT = 10.0

_RUN_STARTED_V2_TO_V3: Final = STEPS["run_started", 2]

#: Relation models built outside the agent, by name, handed to whatever folds a log
#: (``AgentState(models=...)``, ``Session.open(..., models=...)``): the agent cannot import them
#: (dist-oracle reads the simulator's schedule generator). The composition root passes the
#: simulator's (:data:`objsearch.sim.models.SIM_MODELS`) when asked to; nothing is
#: registered by importing anything.
RelationModels = Mapping[str, Callable[[], RelationModel]]
#: The agent's own models only (eq4, beta, memory).
AGENT_MODELS: Final[RelationModels] = MappingProxyType({})


#: The belief's prior weight (episodes) and its short memory's half-life (episodes). Fixed before
#: any run (docs/results.md, "The belief's protocol"), not tuned.
BELIEF_PRIOR_STRENGTH = 1.0
BELIEF_HALF_LIFE_SCENES = 3.0

RELATION_MODELS = (
    "eq4",
    "beta",
    "memory",
    "belief",
    "routine-belief",
    "routine-pooled",
    "dist-oracle",
    "slot-oracle",
)
#: The beliefs over places (agent/belief.py and the two that know the hour).
BELIEF_MODELS = ("belief", "routine-belief", "routine-pooled")
#: The simulator's references (never a default): they read the schedule's generator.
REFERENCE_MODELS = ("dist-oracle", "slot-oracle")
PLANNERS = ("wpl", "rvp", "sdp", "epl")


@dataclass(frozen=True, slots=True)
class RelationSpec:
    """Which fold turns the log into Rel, with every parameter it uses."""

    model: str = "eq4"
    prior_strength: float | None = None
    half_life_tasks: float | None = None
    recent_weight: float | None = None

    def __post_init__(self) -> None:
        if self.model not in RELATION_MODELS:
            raise ObjsearchError(
                f"unknown relation model {self.model!r}; known: {', '.join(RELATION_MODELS)}"
            )
        if self.model in ("beta", "memory", *BELIEF_MODELS) and not (
            self.prior_strength and self.prior_strength > 0
        ):
            raise ObjsearchError(f"the {self.model} relation model needs a prior strength > 0")
        if self.model == "memory" and (
            self.half_life_tasks is None or self.recent_weight is None or self.recent_weight < 0
        ):
            raise ObjsearchError("the memory model needs a half-life and a recent weight >= 0")
        if self.model in BELIEF_MODELS and self.half_life_tasks is None:
            raise ObjsearchError("the belief model needs a half-life (episodes)")
        if self.half_life_tasks is not None and self.half_life_tasks <= 0:
            raise ObjsearchError(f"half-life must be positive, got {self.half_life_tasks}")

    def build(
        self, models: RelationModels = AGENT_MODELS, data: Path | None = None
    ) -> RelationModel:
        """A fresh model of this spec; ``models`` builds those outside the agent. A belief reads
        the run's home from the data folder ``data`` (None: ``datapaths.data_dir()``); a model of
        ``models`` (the simulator's reference oracles) reads only ``datapaths.data_dir()``, and
        refuses another folder."""
        if self.model == "memory":
            from objsearch.agent.memory import InstanceMemory

            assert self.prior_strength is not None and self.half_life_tasks is not None
            return InstanceMemory(
                prior_strength=self.prior_strength,
                half_life_tasks=self.half_life_tasks,
                recent_weight=self.recent_weight or 0.0,
            )
        if self.model == "belief":
            from objsearch.agent.belief import PlaceBelief

            assert self.prior_strength is not None and self.half_life_tasks is not None
            return PlaceBelief(
                prior_strength=self.prior_strength,
                half_life_scenes=self.half_life_tasks,
                data=data,
            )
        if self.model == "routine-belief":
            from objsearch.agent.routine_belief import RoutineBelief

            assert self.prior_strength is not None and self.half_life_tasks is not None
            return RoutineBelief(
                prior_strength=self.prior_strength,
                half_life_scenes=self.half_life_tasks,
                data=data,
            )
        if self.model == "routine-pooled":
            from objsearch.agent.routine_belief import PooledRoutineBelief

            assert self.prior_strength is not None and self.half_life_tasks is not None
            return PooledRoutineBelief(
                prior_strength=self.prior_strength,
                half_life_scenes=self.half_life_tasks,
                data=data,
            )
        if self.model in models:
            if data is not None and data_key(data) != data_key():
                # Built with no folder, it would read another folder's homes and schedules
                # (sim/distribution_oracle.py reads datapaths.data_dir()): an error, not a
                # silently wrong reference.
                raise ObjsearchError(
                    f"the {self.model} relation model reads the data of ${DATA_ENV} (else the "
                    f"bundled data), not a named data folder ({data}): run it with "
                    f"{DATA_ENV}={data}"
                )
            return models[self.model]()
        if self.model in REFERENCE_MODELS:
            raise ObjsearchError(
                f"the {self.model} relation model is a simulation reference that reads the "
                "schedule's generator; fold such a run with the simulator's models "
                "(models=objsearch.sim.models.SIM_MODELS)"
            )
        if self.model == "beta":
            assert self.prior_strength is not None
            return BetaRelations(
                prior_strength=self.prior_strength, half_life_tasks=self.half_life_tasks
            )
        return SceneGraphProjection()

    def record(self) -> RelationsSpec:
        """As ``run_started`` v3 records it."""
        return RelationsSpec(
            model=cast(RelationModelName, self.model),
            prior_strength=self.prior_strength,
            half_life_tasks=self.half_life_tasks,
            recent_weight=self.recent_weight,
        )

    @classmethod
    def from_record(cls, record: RelationsSpec) -> RelationSpec:
        return cls(
            record.model, record.prior_strength, record.half_life_tasks, record.recent_weight
        )


EQ4 = RelationSpec()
MEMORY = RelationSpec("memory", PRIOR_STRENGTH, MEMORY_HALF_LIFE_TASKS, MEMORY_RECENT_WEIGHT)
#: For the belief, ``half_life_tasks`` holds the short memory's half-life in *episodes*.
BELIEF = RelationSpec("belief", BELIEF_PRIOR_STRENGTH, BELIEF_HALF_LIFE_SCENES)
#: The belief that knows the hour (agent/routine_belief.py): the same k and h, per slot too.
ROUTINE_BELIEF = RelationSpec("routine-belief", BELIEF_PRIOR_STRENGTH, BELIEF_HALF_LIFE_SCENES)
#: The same with a home-pooled mixture as a fourth component (agent/routine_belief.py).
ROUTINE_POOLED = RelationSpec("routine-pooled", BELIEF_PRIOR_STRENGTH, BELIEF_HALF_LIFE_SCENES)


@dataclass(frozen=True, slots=True)
class Strategy:
    """A named choice of room order (method), stop planner and relation model."""

    name: str
    method: Method
    description: str
    paper: bool
    relations: RelationSpec = EQ4
    planner: str | None = None  # None: the method's own (WPL, RVP; SDP is WPL with α = 0)

    @property
    def planner_name(self) -> str:
        return self.planner or self.method.value

    @property
    def reference(self) -> bool:
        """A reference searcher that knows what a robot cannot (never a default)."""
        return self.relations.model in REFERENCE_MODELS

    @property
    def randomised(self) -> bool:
        """Whether results depend on the seed (SDP's random room order)."""
        return self.method is Method.SDP


def _beta(half_life: float | None) -> RelationSpec:
    return RelationSpec("beta", PRIOR_STRENGTH, half_life)


STRATEGIES: dict[str, Strategy] = {
    s.name: s
    for s in (
        Strategy("sdp", Method.SDP, "paper baseline: random rooms, nearest stops (α = 0)", True),
        Strategy("rvp", Method.RVP, "paper baseline: rooms and stops by Rel", True),
        Strategy("wpl", Method.WPL, "the paper's method: Eq. 3 with α = 10, Eq. 4 updates", True),
        Strategy(
            "wpl-neg",
            Method.WPL,
            "WPL on a Beta posterior with negative evidence",
            False,
            _beta(None),
        ),
        Strategy(
            "wpl-neg-decay",
            Method.WPL,
            f"WPL on the Beta posterior, evidence half-life {HALF_LIFE_TASKS:g} tasks",
            False,
            _beta(HALF_LIFE_TASKS),
        ),
        Strategy(
            "epl", Method.WPL, "expected-path-length planner, Eq. 4 updates", False, EQ4, "epl"
        ),
        Strategy(
            "epl-neg-decay",
            Method.WPL,
            "expected-path-length planner on the Beta posterior with decay",
            False,
            _beta(HALF_LIFE_TASKS),
            "epl",
        ),
        Strategy(
            "ecost",
            Method.ECOST,
            "rooms by minimum expected cost (exact DP), stops by EPL, Eq. 4 updates",
            False,
            EQ4,
            "epl",
        ),
        Strategy(
            "ecost-memory",
            Method.ECOST,
            "rooms by expected cost, stops by EPL, on a per-instance memory",
            False,
            MEMORY,
            "epl",
        ),
        Strategy(
            "ecost-belief",
            Method.ECOST,
            "rooms by expected cost, stops by EPL, on a probability over places (agent/belief.py)",
            False,
            BELIEF,
            "epl",
        ),
        Strategy(
            "ecost-routine",
            Method.ECOST,
            "ecost-belief's planner on a belief that knows the hour (agent/routine_belief.py)",
            False,
            ROUTINE_BELIEF,
            "epl",
        ),
        Strategy(
            "ecost-routine-pooled",
            Method.ECOST,
            "ecost-routine with a mixture of its components learned from every class of the home",
            False,
            ROUTINE_POOLED,
            "epl",
        ),
        Strategy(
            "global",
            Method.GLOBAL,
            "one plan over every stop of the home (rooms not searched whole), Eq. 4 updates",
            False,
            EQ4,
            "epl",
        ),
        Strategy(
            "global-belief",
            Method.GLOBAL,
            "one plan over every stop of the home (rooms not searched whole), on the belief",
            False,
            BELIEF,
            "epl",
        ),
        Strategy(
            "dist-oracle-global",
            Method.GLOBAL,
            "REFERENCE: dist-oracle's knowledge, planned as global-belief plans",
            False,
            RelationSpec("dist-oracle"),
            "epl",
        ),
        Strategy(
            "dist-oracle",
            Method.ECOST,
            "REFERENCE: knows the schedule's placement distribution (not today's draw)",
            False,
            RelationSpec("dist-oracle"),
            "epl",
        ),
        Strategy(
            "slot-oracle",
            Method.ECOST,
            "REFERENCE: knows the schedule's distribution at each time of day (routine-<seed>)",
            False,
            RelationSpec("slot-oracle"),
            "epl",
        ),
    )
}

PAPER_STRATEGIES = ("sdp", "rvp", "wpl")
#: A strategy's name with this suffix inspects statics longer than 1.5 m from a viewpoint per
#: stretch as well when a search found nothing (``cover``, agent/policy.py); without it, from
#: the single N_s as the paper does. Recorded as the run's ``params.inspection``.
COVER_SUFFIX = "+cover"
#: Chosen by protocol v5's rule, written before its runs (docs/results-belief.md): the belief
#: planned over the whole home, with cover. The paper's method stays ``wpl`` (make demo runs it).
DEFAULT_STRATEGY = "global-belief" + COVER_SUFFIX


def strategy(name: str) -> Strategy:
    """The registered strategy ``name`` (without an inspection suffix)."""
    try:
        return STRATEGIES[name]
    except KeyError:
        raise ObjsearchError(
            f"unknown strategy {name!r}; choose from {', '.join(STRATEGIES)} (each may end in "
            f"{COVER_SUFFIX})"
        ) from None


def split_strategy(name: str) -> tuple[Strategy, str]:
    """The registered strategy a name means and how it inspects statics: ``NAME`` single (the
    paper's N_s), ``NAME+cover`` cover."""
    if name.endswith(COVER_SUFFIX):
        return strategy(name[: -len(COVER_SUFFIX)]), "cover"
    return strategy(name), "single"


def full_strategy_name(registered: str, inspection: str) -> str:
    """The name a user gives for ``registered`` inspecting by ``inspection``: the inverse of
    :func:`split_strategy`."""
    return registered + (COVER_SUFFIX if inspection == "cover" else "")


def strategy_names() -> list[str]:
    """Every name a strategy option accepts: each registered strategy, then each with cover."""
    return [*STRATEGIES, *(name + COVER_SUFFIX for name in STRATEGIES)]


@dataclass(frozen=True, slots=True)
class RunSpec:
    """Everything ``run_started`` records: enough to fold and re-plan the run exactly."""

    home: str
    home_digest: str
    strategy: str
    method: Method
    planner: str
    relations: RelationSpec
    alpha: float = DEFAULT_ALPHA
    update_mode: UpdateMode = UpdateMode.ALL
    seed: int = 0
    support_radius: float = DEFAULT_SUPPORT_RADIUS
    schedule: str | None = None
    params: Mapping[str, Any] = field(default_factory=dict)
    #: The reading of Eq. 2 the scene graph is seeded with (agent/session.py PRIOR_FILES). Not a
    #: run_started field: the first run of a log records it in scene_graph_seeded's source with
    #: the values themselves, which is all a fold or a replay reads.
    prior: str = "vg-cooccurrence"

    def __post_init__(self) -> None:
        if self.planner not in PLANNERS:
            raise ObjsearchError(f"unknown planner {self.planner!r}; known: {', '.join(PLANNERS)}")
        if self.method is Method.GLOBAL and self.planner != "epl":
            raise ObjsearchError(
                f"the global method plans by expected path length; planner {self.planner!r} "
                "does not apply"
            )

    @classmethod
    def of(
        cls,
        home: str,
        home_digest: str,
        strategy_name: str,
        *,
        seed: int = 0,
        update_mode: UpdateMode = UpdateMode.ALL,
        alpha: float = DEFAULT_ALPHA,
        schedule: str | None = None,
        params: Mapping[str, Any] | None = None,
        prior: str = "vg-cooccurrence",
    ) -> RunSpec:
        """The spec of running the strategy ``strategy_name`` (``NAME`` or ``NAME+cover``) on a
        home."""
        chosen, inspection = split_strategy(strategy_name)
        params = dict(params or {})
        if inspection != "single":
            asked = params.setdefault("inspection", inspection)
            if asked != inspection:
                raise ObjsearchError(
                    f"strategy {strategy_name!r} inspects by {inspection}, its params by {asked!r}"
                )
        return cls(
            home=home,
            home_digest=home_digest,
            strategy=chosen.name,
            method=chosen.method,
            planner=chosen.planner_name,
            relations=chosen.relations,
            alpha=alpha,
            update_mode=update_mode,
            seed=seed,
            schedule=schedule,
            params=params,
            prior=prior,
        )

    @classmethod
    def for_home(cls, home: Home, strategy_name: str, **options: Any) -> RunSpec:
        """:meth:`of` for a loaded home (its name and digest)."""
        return cls.of(home.name, home.digest, strategy_name, **options)

    @property
    def inspection(self) -> str:
        """How statics are inspected, recorded in the run's params (absent: the paper's N_s)."""
        return str(self.params.get("inspection", "single"))

    @property
    def name(self) -> str:
        """The strategy as a user names it: ``NAME``, or ``NAME+cover`` for a cover run."""
        return full_strategy_name(self.strategy, self.inspection)

    def with_changes(self, **changes: Any) -> RunSpec:
        return replace(self, **changes)

    def config(self) -> SearchConfig:
        return SearchConfig(
            method=self.method,
            alpha=self.alpha,
            support_radius=self.support_radius,
            seed=self.seed,
            inspection=self.inspection,
            perception=PerceptionModel.from_params(self.params.get("perception")),
        )

    def relation_model(self, models: RelationModels = AGENT_MODELS) -> RelationModel:
        """A fresh relation model of this spec (fold the log into it)."""
        return self.relations.build(models)

    def stop_planner(self) -> StopPlanner:
        if self.planner == "epl":
            return ExpectedPathPlanner()
        if self.planner == "rvp":
            return RelationOrderPlanner(alpha=self.alpha)
        alpha = 0.0 if self.planner == "sdp" else self.alpha
        return WplPlanner(alpha=alpha, name=self.planner)

    def record(self) -> RunStarted:
        """The ``run_started`` record of this spec."""
        return RunStarted(
            home=self.home,
            home_digest=self.home_digest,
            strategy=self.strategy,
            method=self.method.value,
            planner=cast(PlannerName, self.planner),
            relations=self.relations.record(),
            alpha=self.alpha,
            update_mode=self.update_mode.value,
            seed=self.seed,
            support_radius=self.support_radius,
            schedule=self.schedule,
            params=dict(self.params),
        )

    def payload(self) -> dict[str, Any]:
        """``run_started`` v3."""
        return encode(self.record())

    @classmethod
    def from_record(cls, record: RunStarted) -> RunSpec:
        return cls(
            home=record.home,
            home_digest=record.home_digest,
            strategy=record.strategy,
            method=Method(record.method),
            planner=record.planner,
            relations=RelationSpec.from_record(record.relations),
            alpha=float(record.alpha),
            update_mode=UpdateMode(record.update_mode),
            seed=record.seed,
            support_radius=float(record.support_radius),
            schedule=record.schedule,
            params=dict(record.params),
        )

    @classmethod
    def from_payload(cls, payload: Mapping[str, Any]) -> RunSpec:
        """From a ``run_started`` v3 payload (a snapshot's copy of one), or v2: snapshots of runs
        written before v3 hold relations without ``recent_weight``."""
        try:
            record = decode_payload(RunStarted, payload)
        except InvalidEventError as not_v3:
            try:
                record = decode_payload(RunStarted, _RUN_STARTED_V2_TO_V3(dict(payload)))
            except (InvalidEventError, KeyError, TypeError):
                raise not_v3 from None
        return cls.from_record(record)
