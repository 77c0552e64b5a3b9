"""objsearch.sim: the simulated home, its placements and schedules, the long-term loop.

Importing it does nothing else: the distribution oracle (a reference relation model that reads
the schedule's generator, which the agent cannot import) is handed to a fold as
:data:`objsearch.sim.models.SIM_MODELS`.
"""
