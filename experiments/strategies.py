"""The strategy registry lives with the agent (``objsearch.agent.strategies``): a robot runs
them too. This module re-exports it for the benchmark harness."""

from objsearch.agent.strategies import (
    COVER_SUFFIX,
    DEFAULT_STRATEGY,
    HALF_LIFE_TASKS,
    PAPER_STRATEGIES,
    PRIOR_STRENGTH,
    STRATEGIES,
    Strategy,
    full_strategy_name,
    split_strategy,
    strategy,
)

__all__ = [
    "COVER_SUFFIX",
    "DEFAULT_STRATEGY",
    "HALF_LIFE_TASKS",
    "PAPER_STRATEGIES",
    "PRIOR_STRENGTH",
    "STRATEGIES",
    "Strategy",
    "full_strategy_name",
    "split_strategy",
    "strategy",
]
