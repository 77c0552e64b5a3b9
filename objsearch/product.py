"""The composition root of the command-line product: its event store and its relation models.

Nothing is registered by importing anything. The store is the agent's catalogue built into one
value (:data:`objsearch.agent.catalogue.STORE`), handed to every log, reader, snapshot and lake
the commands open; the relation models a fold may build are the agent's own plus, when the
caller asks (any command that reads a log a simulated run may have written), the simulator's
reference models — so folding a ``dist-oracle`` run never depends on what happened to be
imported first.
"""

from __future__ import annotations

from objsearch.agent.catalogue import STORE
from objsearch.agent.strategies import AGENT_MODELS, RelationModels

__all__ = ["STORE", "relation_models"]


def relation_models(*, simulator: bool = False) -> RelationModels:
    """The relation models a fold may build: the agent's, and the simulator's if asked."""
    if not simulator:
        return AGENT_MODELS
    from objsearch.sim.models import SIM_MODELS

    return {**AGENT_MODELS, **SIM_MODELS}
