"""How ``make test``'s workers share the suite (``pytest -n 2 --dist loadscope``, pytest-xdist):
``tests/conftest.py``'s ``pytest_xdist_make_scheduler`` returns :class:`LongestFirst`.

A scope is a test module (its module fixtures are built once), all of ``tests/runtime`` is one
(:data:`TRANSPORT_SCOPE`), and so are the modules that share a dear session fixture
(:data:`SHARED_FIXTURE_SCOPES`: built in one worker, not in both). xdist hands scopes out most tests first, a worker taking the next
when it is nearly done, and never moves a scope once handed out. So a module of one test and a
hundred seconds (``tests/test_lake_log_battery.py``) went out among the last, and the other
worker sat idle while it ran: the last scopes decide when the run ends. :class:`LongestFirst`
hands out the longest expected scope first (LPT), so what is left at the end is short.

What a scope is expected to take is :data:`SCOPE_SECONDS`, or :data:`PER_TEST_SECONDS` a test for
a scope it does not list. It only orders the scopes: no test's outcome depends on it, a stale
figure costs only balance, and the same collection is always handed out in the same order.
"""

from __future__ import annotations

from collections.abc import Mapping, Sized
from typing import Any

from xdist.scheduler import LoadScopeScheduling

#: Every test of tests/runtime is one scope: the transports' DDS domain ids and ports are chosen
#: per process, so two workers would share domains and see each other's nodes.
TRANSPORT_SCOPE = "tests/runtime/"

#: Modules that share a session fixture too dear to build in both workers are one scope, named
#: after the fixture: tests/pipeline/conftest.py's ``built`` is the whole data build (its setup
#: took 17 s and 9 s in two of these modules in the durations run below, one in each worker).
DATA_BUILD_SCOPE = "tests/pipeline/conftest.py::built"
SHARED_FIXTURE_SCOPES: Mapping[str, str] = {
    "tests/pipeline/test_pipeline_build.py": DATA_BUILD_SCOPE,
    "tests/pipeline/test_pipeline_findings.py": DATA_BUILD_SCOPE,
    "tests/pipeline/test_pipeline_home.py": DATA_BUILD_SCOPE,
    "tests/pipeline/test_pipeline_tables.py": DATA_BUILD_SCOPE,
}

#: Seconds per scope: its tests' setup, call and teardown in the 120 slowest of a ``pytest -n 2
#: --durations=120`` run at 861ae3a on a loaded machine (1.5-2x idle), plus
#: :data:`PER_TEST_SECONDS` for each of its other tests; the scopes of 13 s or more whose listed
#: tests make most of it. tests/runtime's figure is a floor (few of its tests were in the 120), and
#: it is the longest scope either way. A scope changed since is that figure times the ratio of its
#: CPU time after the change to before, measured back to back (the query's process forked from a
#: warm one: devtools/query_server.py, median of 3 each); a module added since, its time in a run
#: of its own at load 2-3.
SCOPE_SECONDS: Mapping[str, float] = {
    TRANSPORT_SCOPE: 300,
    "tests/test_wheel.py": 128,
    "tests/test_lake_log_battery.py": 96,  # 191 x 37.5 / 74.3 CPU-s
    "tests/pipeline/bags/test_bags_lake.py": 98,
    "tests/pipeline/bags/test_bags_battery.py": 98,
    "tests/events/test_lake_table_s3.py": 93,
    "tests/experiments/test_results_commands.py": 87,
    "tests/events/test_lake_table_kill.py": 78,
    "tests/experiments/test_report.py": 65,
    "tests/replay/test_scene_graph_properties.py": 60,
    "tests/pipeline/bags/test_bags_damage.py": 60,
    "tests/experiments/test_figures.py": 56,
    "tests/events/test_crash.py": 45,
    "tests/pipeline/bags/test_bags_sessions.py": 43,
    "tests/test_cli_query.py": 23,  # 43 x 33.6 / 61.8 CPU-s
    "tests/events/test_logfuzz.py": 42,
    "tests/pipeline/bags/test_bags_twice.py": 40,
    "tests/pipeline/test_pipeline_user_homes.py": 35,
    "tests/experiments/test_bench.py": 35,
    "tests/pipeline/bags/test_bags_engines.py": 31,
    "tests/test_lake_battery.py": 21,  # 30 x 9.7 / 14.1 CPU-s
    # test_pipeline_build 23, findings 18, home 20, tables 2 (0.35 s a test), less one data build
    DATA_BUILD_SCOPE: 50,
    "tests/pipeline/bags/test_bags_fleet.py": 29,
    "tests/sim/test_demo.py": 27,
    "tests/replay/test_source.py": 26,
    "tests/sim/test_world.py": 21,
    "tests/events/test_lake_table.py": 19,
    "tests/experiments/test_table1_sets.py": 19,
    "tests/examples/test_notebooks.py": 19,
    "tests/agent/test_mapping.py": 17,
    "tests/sim/test_mapeval.py": 16,
    "tests/test_lake_fields_battery.py": 16,
    "tests/pipeline/bags/test_bags_ingest.py": 16,
    "tests/experiments/test_report_protocol.py": 16,
    "tests/experiments/test_sensitivity.py": 14,
    "tests/experiments/test_report_html.py": 13,
    "tests/test_query_server.py": 11,
}
#: A test of a scope :data:`SCOPE_SECONDS` does not list (the same run: about 0.35 s a test).
PER_TEST_SECONDS = 0.35


def scope_of(nodeid: str) -> str:
    """The scope of a test: its module, :data:`TRANSPORT_SCOPE` for all of tests/runtime, or
    the group :data:`SHARED_FIXTURE_SCOPES` puts its module in."""
    if nodeid.startswith(TRANSPORT_SCOPE):
        return TRANSPORT_SCOPE
    module = nodeid.split("::", 1)[0]
    return SHARED_FIXTURE_SCOPES.get(module, module)


def expected_seconds(scope: str, tests: int) -> float:
    """What a scope of ``tests`` tests is expected to take (only to order scopes)."""
    return SCOPE_SECONDS.get(scope, PER_TEST_SECONDS * tests)


def longest(workqueue: Mapping[str, Sized]) -> str:
    """The scope of ``workqueue`` (scope -> its tests) expected to take longest; of equals, the
    first."""
    return max(workqueue, key=lambda scope: expected_seconds(scope, len(workqueue[scope])))


class LongestFirst(LoadScopeScheduling):  # type: ignore[misc]
    """xdist's scope scheduling with a scope a module (all of tests/runtime one, and the modules
    of :data:`SHARED_FIXTURE_SCOPES` one a fixture), each handed out longest expected first.
    (xdist's ``loadgroup`` marks would say the same scopes, but with pytest 9.2 they have no
    effect: xdist 3.8 renames ``item._nodeid``, which pytest no longer reads.)"""

    def _split_scope(self, nodeid: str) -> str:
        return scope_of(nodeid)

    def _assign_work_unit(self, node: Any) -> None:
        # xdist pops the front of its queue: put the longest scope there first (the queue holds
        # every scope from the start, so this is the whole order, decided once per hand-out)
        self.workqueue.move_to_end(longest(self.workqueue), last=False)
        super()._assign_work_unit(node)


__all__ = [
    "DATA_BUILD_SCOPE",
    "PER_TEST_SECONDS",
    "SCOPE_SECONDS",
    "SHARED_FIXTURE_SCOPES",
    "TRANSPORT_SCOPE",
    "LongestFirst",
    "expected_seconds",
    "longest",
    "scope_of",
]
