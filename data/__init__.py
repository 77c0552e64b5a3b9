"""The derived data, shipped as package data (``objsearch.data``); see ``agent/datapaths.py``.

Everything else in this folder is written by ``objsearch data build`` (``PROVENANCE.md``).
"""
