"""What every backend of the lake passes: the fleet lake on a Delta table
(:class:`objsearch.events.lake.TableLake`), in a folder or a bucket.

:class:`LakeContract` is the abstract test case (as ``eventsourcing`` tests its recorders: one
case, one subclass a backend, ``tests/events/contract/test_lake_contract.py``). It drives what a
lake does: adding an event log as a run (``add_log``), ``runs``, ``find``, ``holding``,
``read_events``, ``read_tables``, ``commit_tables`` and the views queries read
(:func:`objsearch.replay.analytics.open_analytics`). What differs by backend (removing a run,
what ``verify`` returns, what "nothing was written" looks like) a subclass says through a hook;
where one cannot do a thing, it skips that case with a reason.
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from collections import Counter
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, ClassVar, Generic, Protocol, TypeVar

import pyarrow as pa
import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import Event, EventLog, read_log
from objsearch.events.arrow import events_to_tables
from objsearch.events.lake import LakeError
from objsearch.events.sql_limits import close
from objsearch.replay.analytics import open_analytics, run_query

from ..lake_logs import small_log
from ..payloads import EXAMPLES


class RunLike(Protocol):
    """What a committed run says of itself, in either lake."""

    @property
    def robot(self) -> str: ...
    @property
    def date(self) -> str: ...
    @property
    def run(self) -> str: ...
    @property
    def rows(self) -> Mapping[str, int]: ...
    @property
    def identity(self) -> Mapping[str, str]: ...
    @property
    def events(self) -> int: ...


R = TypeVar("R", bound=RunLike)


class LakeLike(Protocol[R]):
    """The reads and the commit both lakes offer, with one signature."""

    def runs(self) -> list[R]: ...
    def find(self, robot: str, run: str) -> R | None: ...
    def holding(self, identity: Mapping[str, str]) -> list[R]: ...
    def read_events(self, run: R) -> list[Event]: ...
    def read_tables(self, run: R) -> dict[str, pa.Table]: ...


L = TypeVar("L", bound=LakeLike[Any])
#: ``compact_log`` or ``add_log``: seal an event log into the lake as one run.
AddLog = Callable[..., Any]


def damage_file(path: Path, how: str) -> None:
    """Cut the last bytes off ``path`` ("cut") or delete it ("missing")."""
    if how == "cut":
        path.write_bytes(path.read_bytes()[:-10])
    else:
        path.unlink()


class LakeContract(ABC, Generic[L, R]):
    """The lake contract. A subclass names its backend (``open``, ``add``) and the hooks."""

    #: Why this backend's files cannot be damaged one at a time (skips those cases), or None.
    no_file_damage: ClassVar[str | None] = None
    #: The cases a subclass runs, when not all (the others are skipped, ``narrowed`` says why).
    cases: ClassVar[frozenset[str] | None] = None
    narrowed: ClassVar[str] = ""

    @pytest.fixture(autouse=True)
    def _only_the_cases_of_this_backend(self, request: pytest.FixtureRequest) -> None:
        if self.cases is not None and request.function.__name__ not in self.cases:
            pytest.skip(self.narrowed)

    @pytest.fixture
    def root(self, tmp_path: Path) -> Path | str:
        """Where the lake lives (a subclass on a bucket overrides it)."""
        return tmp_path / "lake"

    @abstractmethod
    def open(self, root: Path | str) -> L: ...

    @abstractmethod
    def add(
        self, log: Path, lake: L, *, robot: str, run: str | None = None, **kwargs: Any
    ) -> R: ...

    @abstractmethod
    def remove(self, lake: L, info: R) -> None: ...

    @abstractmethod
    def written(self, lake: L) -> object:
        """Something that changes whenever the lake is written to."""

    @abstractmethod
    def damage(self, lake: L, info: R, event_type: str, how: str) -> str:
        """Damage (``how``: "cut" or "missing") the file holding ``info``'s rows of
        ``event_type``; returns the file's name, which reports must name."""

    @abstractmethod
    def reported(self, lake: L) -> list[str]:
        """What ``verify`` reports as damaged, one text a damaged thing."""

    def run_names(self, lake: L) -> list[str]:
        return [r.run for r in lake.runs()]

    # -- a run in, a run out --------------------------------------------------------------------

    def test_a_run_added_reads_back_equal_to_its_log(
        self, root: Path | str, tmp_path: Path
    ) -> None:
        lake = self.open(root)
        log = small_log(tmp_path / "log")
        info = self.add(log, lake, robot="r2d2")
        assert (info.robot, info.date, info.run) == ("r2d2", "2023-11-14", "run-a")
        assert lake.runs() == [info] and lake.find("r2d2", "run-a") == info
        events = list(read_log(log, store=STORE))  # upcast, as the lake holds them
        assert lake.read_events(info) == events
        tables = events_to_tables(iter(events), STORE)
        got = lake.read_tables(info)
        assert sorted(got) == sorted(tables)
        for event_type, table in tables.items():
            assert got[event_type].equals(table), event_type
        assert dict(info.rows) == Counter(e.type for e in events)
        assert info.rows["search_failed"] == 4 and info.events == len(EXAMPLES) + 4

    def test_adding_the_same_log_again_is_a_no_op(self, root: Path | str, tmp_path: Path) -> None:
        lake = self.open(root)
        log = small_log(tmp_path / "log")
        info = self.add(log, lake, robot="sim")
        before = self.written(lake)
        assert self.add(log, lake, robot="sim") == info
        assert self.written(lake) == before  # nothing written
        assert lake.runs() == [info]

    def test_other_content_under_a_runs_name_needs_replace(
        self, root: Path | str, tmp_path: Path
    ) -> None:
        lake = self.open(root)
        log = small_log(tmp_path / "log")
        self.add(log, lake, robot="r")
        with EventLog.open(log, "run-a", store=STORE) as writer:
            writer.append("search_failed", {"reason": "later"}, time_ns=1000)
        before = self.written(lake)
        with pytest.raises(LakeError, match=r"run 'run-a'.*other content.*replace=True"):
            self.add(log, lake, robot="r")
        assert self.written(lake) == before
        new = self.add(log, lake, robot="r", replace=True)
        assert new.rows["search_failed"] == 5
        assert lake.runs() == [new]
        assert lake.read_events(new) == list(read_log(log, store=STORE))

    def test_a_run_of_another_log_replaces_one_of_other_types(
        self, root: Path | str, tmp_path: Path
    ) -> None:
        # The replacement holds one type the old run lacks rows of and lacks all of its others.
        lake = self.open(root)
        self.add(small_log(tmp_path / "a", stream="s"), lake, robot="r", run="x")
        with EventLog.open(tmp_path / "b", "s", wall_clock=lambda: 0, store=STORE) as writer:
            for i in range(5):
                writer.append("search_failed", {"reason": f"r{i}"}, time_ns=i)
        new = self.add(tmp_path / "b", lake, robot="r", run="x", replace=True)
        assert [(r.run, r.events, dict(r.rows)) for r in lake.runs()] == [
            ("x", 5, {"search_failed": 5})
        ]
        assert len(lake.read_events(new)) == 5

    def test_a_removed_run_is_gone_and_can_be_added_again(
        self, root: Path | str, tmp_path: Path
    ) -> None:
        lake = self.open(root)
        keep = self.add(small_log(tmp_path / "a", stream="a"), lake, robot="r")
        gone = self.add(small_log(tmp_path / "b", stream="b"), lake, robot="r")
        self.remove(lake, gone)
        assert lake.runs() == [keep] and lake.find("r", "b") is None
        assert lake.holding(dict(gone.identity)) == []  # its identity is free again
        again = self.add(tmp_path / "b", lake, robot="r")
        assert self.run_names(lake) == ["a", "b"]
        assert len(lake.read_events(again)) == gone.events

    def test_a_log_is_held_once_whatever_the_runs_name(
        self, root: Path | str, tmp_path: Path
    ) -> None:
        lake = self.open(root)
        log = small_log(tmp_path / "log")
        info = self.add(log, lake, robot="r", run="one")
        assert lake.holding({"first_event_id": info.identity["first_event_id"]}) == [info]
        with pytest.raises(LakeError, match="already in the lake as run 'one'"):
            self.add(log, lake, robot="r", run="two")
        assert self.run_names(lake) == ["one"]

    # -- what is refused ------------------------------------------------------------------------

    def test_bad_partition_values_are_refused(self, root: Path | str, tmp_path: Path) -> None:
        lake = self.open(root)
        log = small_log(tmp_path / "log")
        refused: list[tuple[dict[str, str], str]] = [
            ({"robot": "../x"}, "robot name '../x'"),
            ({"robot": "r", "run": "a b"}, "run name 'a b'"),
            ({"robot": "r", "date": "yesterday"}, "not an ISO date"),
            # A `$` regex matches before a trailing newline; the check is a full match.
            ({"robot": "x\n"}, r"robot name 'x\\n'"),
            ({"robot": "r", "run": "a\n"}, r"run name 'a\\n'"),
        ]
        for kwargs, message in refused:
            with pytest.raises(LakeError, match=message):
                self.add(log, lake, **kwargs)
        assert self.run_names(lake) == []  # nothing of a refused commit is there

    def test_commit_tables_refuses_bad_names_and_tables_that_do_not_fit_their_schema(
        self, root: Path | str
    ) -> None:
        commit: Any = self.open(root).commit_tables  # type: ignore[attr-defined]
        with pytest.raises(LakeError, match="must start with a letter"):
            commit({}, robot="r", run="../x", date="2024-01-01")
        with pytest.raises(LakeError, match="not an ISO date"):
            commit({}, robot="r", run="x", date="yesterday")
        table = pa.table({"event_id": ["x"], "stream": ["s"]})
        with pytest.raises(LakeError, match="missing"):
            commit({"moved": table}, robot="r", run="a", date="2024-01-01")

    # -- damage and counts ----------------------------------------------------------------------

    @pytest.mark.parametrize("how", ["cut", "missing"])
    def test_a_damaged_file_is_left_out_of_queries_and_reported(
        self, root: Path | str, tmp_path: Path, how: str, caplog: pytest.LogCaptureFixture
    ) -> None:
        if self.no_file_damage:
            pytest.skip(self.no_file_damage)
        lake = self.open(root)
        self.add(small_log(tmp_path / "a", stream="a"), lake, robot="r")
        hurt = self.add(small_log(tmp_path / "b", stream="b"), lake, robot="r")
        assert self.reported(lake) == []
        name = self.damage(lake, hurt, "search_failed", how)
        with caplog.at_level(logging.WARNING):
            con = open_analytics(root)
        try:
            assert run_query(con, "SELECT run, count(*) FROM search_failed GROUP BY run")[1] == [
                ("a", 4)
            ]
        finally:
            close(con)
        assert name in caplog.text and "left out" in caplog.text
        [report] = self.reported(lake)
        assert name in report

    def test_queries_count_what_the_runs_hold(self, root: Path | str, tmp_path: Path) -> None:
        lake = self.open(root)
        for i, stream in enumerate(("a", "b")):
            self.add(small_log(tmp_path / stream, stream=stream, n=i), lake, robot="r")
        con = open_analytics(root)
        try:
            rows = run_query(con, "SELECT run, count(*) FROM events GROUP BY run ORDER BY run")[1]
            failed = run_query(con, "SELECT count(*) FROM search_failed")[1]
        finally:
            close(con)
        assert rows == [(r.run, r.events) for r in lake.runs()]
        assert [n for _, n in rows] == [len(EXAMPLES) + 1, len(EXAMPLES) + 2]
        assert failed == [(sum(r.rows["search_failed"] for r in lake.runs()),)] == [(3,)]
