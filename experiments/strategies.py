"""Search strategies as plug-ins: a relation model (the fold) and a stop planner, by name.

The paper's three methods (SDP, RVP, WPL) use Eq. 4 and their own planners. Ours swap one seam
each, never forking the policy: ``wpl-neg`` and ``wpl-neg-decay`` fold the same log into a Beta
posterior (negative evidence, decay toward the prior); ``epl`` orders stops by expected path length;
``epl-neg-decay`` combines both. The paper's WPL stays the default until ours win on held-out homes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from objsearch.agent.errors import ObjsearchError
from objsearch.agent.planner import ExpectedPathPlanner, StopPlanner
from objsearch.agent.policy import Method, SearchConfig
from objsearch.agent.relations import BetaRelations, RelationModel
from objsearch.agent.scene_graph import SceneGraphProjection

#: Pseudo-observations of the Visual Genome prior in the Beta model. Fixed a priori (a weak prior
#: worth two searches), not tuned on any home.
PRIOR_STRENGTH = 2.0
#: Half-life of evidence, in tasks: 64 is one scene of the long-term protocol (8 targets × 8
#: starts). Fixed a priori, not tuned.
HALF_LIFE_TASKS = 64.0


@dataclass(frozen=True)
class Strategy:
    name: str
    method: Method  # room order (and planner, unless ``planner`` is given)
    description: str
    paper: bool
    relations: Callable[[], RelationModel]
    planner: Callable[[], StopPlanner] | None = None

    def config(self, seed: int) -> SearchConfig:
        return SearchConfig(method=self.method, alpha=10.0, seed=seed)

    @property
    def randomised(self) -> bool:
        """Whether results depend on the seed (SDP's random room order)."""
        return self.method is Method.SDP


def _beta(half_life: float | None) -> Callable[[], RelationModel]:
    return lambda: BetaRelations(prior_strength=PRIOR_STRENGTH, half_life_tasks=half_life)


STRATEGIES: dict[str, Strategy] = {
    s.name: s
    for s in (
        Strategy(
            "sdp",
            Method.SDP,
            "paper baseline: random rooms, nearest stops (α = 0)",
            True,
            SceneGraphProjection,
        ),
        Strategy(
            "rvp", Method.RVP, "paper baseline: rooms and stops by Rel", True, SceneGraphProjection
        ),
        Strategy(
            "wpl",
            Method.WPL,
            "the paper's method: Eq. 3 with α = 10, Eq. 4 updates",
            True,
            SceneGraphProjection,
        ),
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
            "epl",
            Method.WPL,
            "expected-path-length planner, Eq. 4 updates",
            False,
            SceneGraphProjection,
            ExpectedPathPlanner,
        ),
        Strategy(
            "epl-neg-decay",
            Method.WPL,
            "expected-path-length planner on the Beta posterior with decay",
            False,
            _beta(HALF_LIFE_TASKS),
            ExpectedPathPlanner,
        ),
    )
}

PAPER_STRATEGIES = ("sdp", "rvp", "wpl")
DEFAULT_STRATEGY = "wpl"


def strategy(name: str) -> Strategy:
    try:
        return STRATEGIES[name]
    except KeyError:
        raise ObjsearchError(
            f"unknown strategy {name!r}; choose from {', '.join(STRATEGIES)}"
        ) from None
