"""How ``make test``'s two workers share the suite (devtools/xdist_scopes.py): xdist's own
scheduling code drives two stand-in workers (they record what they are sent and finish each test
when told), so the order checked is the order a run hands scopes out in."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

from devtools.xdist_scopes import (
    DATA_BUILD_SCOPE,
    PER_TEST_SECONDS,
    SCOPE_SECONDS,
    SHARED_FIXTURE_SCOPES,
    TRANSPORT_SCOPE,
    LongestFirst,
    expected_seconds,
    scope_of,
)

REPO = Path(__file__).resolve().parents[1]


class Worker:
    """What xdist's scheduler asks of a worker: take test indexes (a scope's), shut down. Each
    batch's first test is added to ``batches``, which all workers share."""

    def __init__(self, name: str, batches: list[int]) -> None:
        self.gateway = SimpleNamespace(id=name)
        self.shutting_down = False
        self.sent: list[int] = []
        self.batches = batches

    def send_runtest_some(self, indexes: list[int]) -> None:
        self.batches.append(indexes[0])
        self.sent += indexes

    def shutdown(self) -> None:
        self.shutting_down = True


#: A collection in pytest's order: a module of many short tests first, the long one-test battery
#: near the end (as in the suite), tests/runtime in two modules, a module the table does not list.
COLLECTION = [
    *(f"tests/agent/test_planner.py::test_{i}" for i in range(157)),
    "tests/runtime/test_end_to_end.py::test_a",
    "tests/runtime/test_nav2.py::test_b",
    *(f"tests/sim/test_unlisted.py::test_{i}" for i in range(3)),
    "tests/test_lake_log_battery.py::test_battery",
    *(f"tests/test_wheel.py::test_{i}" for i in range(11)),
    "tests/pipeline/test_pipeline_build.py::test_build",
    "tests/pipeline/test_pipeline_home.py::test_home",
]


def _run(collection: list[str]) -> tuple[list[str], dict[str, set[str]]]:
    """The scopes in the order they were handed out, and the worker each test ran in, with two
    workers finishing one test at a time in turn."""
    config = SimpleNamespace(
        getvalue=lambda name: ["2*popen"], option=SimpleNamespace(loadscopereorder=True)
    )
    scheduler = LongestFirst(config)
    batches: list[int] = []
    workers = [Worker("gw0", batches), Worker("gw1", batches)]
    for worker in workers:
        scheduler.add_node(worker)
        scheduler.add_node_collection(worker, collection)
    ran_in: dict[str, set[str]] = {}
    done = [0, 0]
    scheduler.schedule()
    while any(done[w] < len(worker.sent) for w, worker in enumerate(workers)):
        for w, worker in enumerate(workers):
            if done[w] < len(worker.sent):
                nodeid = collection[worker.sent[done[w]]]
                ran_in.setdefault(nodeid.split("::")[0], set()).add(worker.gateway.id)
                scheduler.mark_test_complete(worker, worker.sent[done[w]])
                done[w] += 1
    assert sorted(i for worker in workers for i in worker.sent) == list(range(len(collection)))
    return [scope_of(collection[first]) for first in batches], ran_in


def test_scopes_are_handed_out_longest_expected_first() -> None:
    handed_out, _ = _run(COLLECTION)
    assert handed_out == [
        TRANSPORT_SCOPE,
        "tests/test_wheel.py",
        "tests/test_lake_log_battery.py",  # one test: most-tests-first handed it out last
        "tests/agent/test_planner.py",  # not listed: 157 x PER_TEST_SECONDS
        DATA_BUILD_SCOPE,
        "tests/sim/test_unlisted.py",
    ]


def test_a_module_and_all_of_tests_runtime_each_run_in_one_worker() -> None:
    _, ran_in = _run(COLLECTION)
    runtime = ran_in["tests/runtime/test_end_to_end.py"] | ran_in["tests/runtime/test_nav2.py"]
    assert len(runtime) == 1
    assert all(len(workers) == 1 for workers in ran_in.values())


def test_the_modules_sharing_the_data_build_run_in_one_worker() -> None:
    """tests/pipeline/conftest.py's session fixture ``built`` (the whole data build) is made
    once per worker that asks for it: its modules are one scope, so it is made once."""
    modules = list(SHARED_FIXTURE_SCOPES)  # alone, each its own scope, one would go to each worker
    _, ran_in = _run([f"{module}::test_{i}" for module in modules for i in range(30)])
    assert len(set().union(*(ran_in[module] for module in modules))) == 1


def test_a_scope_the_table_does_not_list_is_expected_to_take_its_tests_times_the_average() -> None:
    assert expected_seconds("tests/sim/test_unlisted.py", 20) == 20 * PER_TEST_SECONDS
    assert (
        expected_seconds("tests/test_lake_log_battery.py", 1)
        == SCOPE_SECONDS["tests/test_lake_log_battery.py"]
    )


def test_every_scope_the_tables_list_is_a_test_module_or_folder_or_a_conftest() -> None:
    """A renamed module would drop out of the order (or its group) silently."""
    listed = [*SCOPE_SECONDS, *SHARED_FIXTURE_SCOPES]
    missing = [scope for scope in listed if not (REPO / scope.split("::")[0]).exists()]
    assert missing == []
