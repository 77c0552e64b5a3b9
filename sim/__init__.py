"""objsearch.sim: the simulated home, its placements and schedules, the long-term loop.

Importing it registers the distribution oracle (a reference relation model that reads the
schedule's generator) with the agent's strategies, which cannot import the simulator.
"""

from objsearch.agent.strategies import register_relation_model
from objsearch.sim.distribution_oracle import DistributionOracle

register_relation_model("dist-oracle", DistributionOracle)
