"""The simulator's reference relation models by name, for a fold of a log whose spec may name one
(``AgentState(models=SIM_MODELS)``, ``Session.open(..., models=SIM_MODELS)``; the CLI's
``objsearch.product.relation_models(simulator=True)``).

Each is built by a function that imports its class when called: the oracles read every schedule
kind's generator (:mod:`objsearch.sim.distribution_oracle`), which a command that only might fold
such a run (one search, a replay) should not import.
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Final

from objsearch.agent.relations import RelationModel
from objsearch.agent.strategies import RelationModels


def distribution_oracle() -> RelationModel:
    """``dist-oracle``: the schedule generator's own distribution of where each object is."""
    from objsearch.sim.distribution_oracle import DistributionOracle

    return DistributionOracle()


def slot_oracle() -> RelationModel:
    """``slot-oracle``: the same, per slot of the day on a routine schedule."""
    from objsearch.sim.distribution_oracle import SlotOracle

    return SlotOracle()


SIM_MODELS: Final[RelationModels] = MappingProxyType(
    {"dist-oracle": distribution_oracle, "slot-oracle": slot_oracle}
)
