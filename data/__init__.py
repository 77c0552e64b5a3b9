"""The derived data, shipped as package data (``objsearch.data``); see ``objsearch/paths.py``.

Everything else in this folder is written by ``objsearch data build`` (``PROVENANCE.md``).
"""
