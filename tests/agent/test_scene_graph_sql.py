"""The agent's catalogue hands the lake Eq. 4's tables, under the names and versions committed
runs already hold (a change here would make every run's files look stale)."""

from __future__ import annotations

from objsearch.agent import scene_graph_sql
from objsearch.agent.catalogue import CATALOGUE
from objsearch.events.catalogue import installed
from objsearch.events.derived import derived_tables


def test_the_installed_catalogue_is_the_agents_with_the_eq4_tables() -> None:
    assert installed() is CATALOGUE
    assert CATALOGUE.derived == scene_graph_sql.DERIVED_TABLES
    assert [t.file_name for t in derived_tables()] == [
        "searches.v3.parquet",
        "eq4_updates.v2.parquet",
        "scene_graph.v2.parquet",
    ]
