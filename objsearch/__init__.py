"""objsearch: long-term object search with an incrementally updated scene graph."""

__version__ = "0.1.0"
