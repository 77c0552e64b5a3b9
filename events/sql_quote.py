"""SQL text: identifiers and literals quoted for DuckDB. A leaf, so the lake, the views
(:mod:`.sql`) and the limits (:mod:`.sql_limits`) can all quote without importing each other."""

from __future__ import annotations


def quote_ident(name: str) -> str:
    return '"' + name.replace('"', '""') + '"'


def quote_literal(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"
