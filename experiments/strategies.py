"""The strategy registry lives with the agent (``objsearch.agent.strategies``): a robot runs
them too. This module re-exports it for the benchmark harness."""

from objsearch.agent.strategies import (
    DEFAULT_STRATEGY,
    HALF_LIFE_TASKS,
    PAPER_STRATEGIES,
    PRIOR_STRENGTH,
    STRATEGIES,
    Strategy,
    strategy,
)

__all__ = [
    "DEFAULT_STRATEGY",
    "HALF_LIFE_TASKS",
    "PAPER_STRATEGIES",
    "PRIOR_STRENGTH",
    "STRATEGIES",
    "Strategy",
    "strategy",
]
