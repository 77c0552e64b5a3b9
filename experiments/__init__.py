"""Experiments: the paper's tables in simulation, our strategies beside them, on more homes."""
