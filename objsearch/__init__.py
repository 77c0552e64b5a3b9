"""objsearch: long-term object search with an incrementally updated scene graph."""

# The composition root of the event model: the store (objsearch.events) knows no robot and is
# handed the agent's catalogue (records, upcasters) here, once, so read_log(dir) and every other
# store default read the domain's events wherever they are imported from.
from objsearch.agent.catalogue import CATALOGUE as _CATALOGUE
from objsearch.events.catalogue import install as _install

__version__ = "0.1.0"

_install(_CATALOGUE)
