"""The fleet lake's bookkeeping: the table's log against the runs' records (each ``_run`` row's
rows per type), the head record and the runs' application transactions (:class:`LakeChecks`)."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from contextlib import suppress
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc

from ..store import Store
from .head import HEAD_FILE, recorded_head
from .read import LakeReads
from .schema import (
    _DERIVED_PREFIX,
    _RECORD_ERRORS,
    RUN_COLUMN,
    RUN_TYPE,
    DataFile,
    TableLakeError,
    TableRun,
)
from .transactions import IDENTITY_INDEX_APP, _app_id, _identity_app


class LakeChecks(LakeReads):
    """The fleet lake, its table checked against its runs' records."""

    def check_runs(self, table: Any | None = None) -> list[tuple[DataFile, str]]:
        """The ``_run`` files that cannot be read (:meth:`read_runs`), after checking the table
        against the runs' records from the table's log and the ``_run`` rows' ``rows`` alone
        (no event read; each distinct record parsed once): each partition's rows, by the log's
        statistics, against what the records add up to — events, derived tables, one ``_run``
        row a run — no run recorded twice, no commit after the checkpoint emptied
        (:meth:`_empty_commits`), and the table's version against the latest this lake
        recorded committing (:data:`HEAD_FILE`). Raises
        :class:`TableLakeError` saying what disagrees: a commit file edited (an ``add``
        removed) or the newest deleted, whose rows no query would then read. What it cannot
        see: a ``_run`` file that cannot be read hides its runs' rows from the count (only
        more rows than the readable records name is then allowed); derived rows of a run
        committed before they were recorded; a log edited so the totals still agree (two
        edits; ``lake verify`` counts each run's rows). The read paths' guard: ``query``,
        ``lake ls``, ``lake add``, ``lake compact``."""
        table = self.table() if table is None else table
        files = self.data_files(table)
        good, unreadable = self._check_files([f for f in files if f.kind == RUN_TYPE], hashes=True)
        columns = {
            "robot": pc.field("robot"),
            "run": pc.field("run"),
            "rows": pc.field(RUN_COLUMN, "rows"),
        }

        def tally(some: list[DataFile]) -> tuple[dict[str, int], list[str]]:
            if not some:
                return _tally(pa.table({k: pa.array([], pa.string()) for k in columns}), self.store)
            rows = self.files_dataset(some, checksums=True).to_table(columns=columns)
            return _tally(rows, self.store)

        try:
            recorded, twice = tally(good)
        except (OSError, pa.ArrowException, *_RECORD_ERRORS):
            readable = []  # one at a time, to name the file that does not read
            for f in good:
                try:
                    tally([f])
                    readable.append(f)
                except (OSError, pa.ArrowException) as exc:
                    unreadable.append((f, f"{f.path} does not decode: {str(exc)[:300]}"))
                except _RECORD_ERRORS as exc:
                    unreadable.append(
                        (f, f"{f.path} holds a row that is no run's record ({exc!r})")
                    )
            recorded, twice = tally(readable)
        problems = self._log_problems(table, writing=False) + self._empty_commits()
        problems += [f"run {label} is recorded more than once" for label in twice]
        problems += _count_problems(files, recorded, unreadable)
        if problems:
            said = "; ".join(problems[:3]) + (
                f"; and {len(problems) - 3} more" if len(problems) > 3 else ""
            )
            raise TableLakeError(
                f"{self.root}: the table does not hold what its runs recorded, so an answer from "
                f"it would be wrong: {said}. A commit file of the table's log "
                f"({self.uri}/_delta_log) was edited or deleted; `objsearch lake verify "
                f"{self.root}` names the runs. Nothing was read or changed"
            )
        return unreadable

    def _log_problems(self, table: Any, *, writing: bool = True) -> list[str]:
        """What is wrong with the table's log that delta-rs reads past: a version older than
        one this lake recorded committing (:data:`HEAD_FILE`: the newest commit files were
        deleted, and the runs they committed with them), and — ``writing`` — the latest
        version's commit file missing (read from its checkpoint, the table cannot take a
        commit: delta-rs fails it with "Invalid table version")."""
        problems = []
        version = int(table.version())
        head = recorded_head(self)
        if head is not None and head > version:
            # The table handed in may only be older than a commit another writer made since it
            # was loaded (the head record is written after that commit): damage only if the log
            # as it is now still ends before the recorded head.
            version = max(version, int(self.table().version()))
        if head is not None and head > version:
            problems.append(
                f"the log ends at version {version}, but a commit of version {head} was made "
                f"({HEAD_FILE} records it): the commit file(s) of version {version + 1} to "
                f"{head} are missing, with every row they committed"
            )
        if writing and not self.remote:
            latest = Path(self.uri) / "_delta_log" / f"{version:020d}.json"
            if not latest.exists():
                problems.append(
                    f"the commit file of the latest version, _delta_log/{latest.name}, is "
                    "missing (the version reads from its checkpoint, but no commit can follow "
                    "it): restore the file"
                )
        return problems

    def _empty_commits(self) -> list[str]:
        """Commit files of the log (local) after its latest checkpoint — those a reader reads
        — that hold no action but their ``commitInfo``: every commit this lake makes adds,
        removes or records something, so one cut down to its first line took a whole commit
        out (a run with its record, which no count can see). A checkpoint comes with each
        compaction, so these are the commits since the last one (a ``lake add`` compacts past
        :data:`COMPACT_AT_FILES` files)."""
        if self.remote:
            return []
        log = Path(self.uri) / "_delta_log"
        since = -1
        with suppress(OSError, ValueError, TypeError, KeyError):
            since = int(json.loads((log / "_last_checkpoint").read_text())["version"])
        problems = []
        for path in sorted(log.glob("[0-9]*[0-9].json")):
            if not path.stem.isdigit() or int(path.stem) <= since:
                continue
            try:
                lines = path.read_text(encoding="utf-8").splitlines()
            except (OSError, UnicodeDecodeError) as exc:
                problems.append(f"commit file {path.name} cannot be read: {exc}")
                continue
            if _writes(lines) and not any(
                line.strip() and not line.startswith('{"commitInfo"') for line in lines
            ):
                problems.append(
                    f"commit file {path.name} holds no action, only its commitInfo: what it "
                    "committed (a run, with its record) is not in the table"
                )
        return problems

    def check_writable(self, table: Any) -> None:
        """Raise :class:`TableLakeError` if the table's log cannot take a commit
        (:meth:`_log_problems`)."""
        problems = self._log_problems(table)
        if problems:
            raise TableLakeError(f"{self.root}: the table's log is damaged: {'; '.join(problems)}")

    def _transaction_problems(self, table: Any, runs: Sequence[TableRun]) -> list[tuple[str, str]]:
        """Runs whose application transactions (what a writer asks instead of reading the
        ``_run`` rows) are missing from the table's log: adding their log again would count
        it twice."""
        indexed = table.transaction_version(IDENTITY_INDEX_APP) is not None
        problems = []
        for r in runs:
            apps = [_app_id(r.robot, r.run)]
            if indexed:
                apps += [_identity_app(k, v) for k, v in sorted(r.identity.items()) if v]
            missing = [a for a in apps if table.transaction_version(a) is None]
            if missing and not r.run.startswith("_"):
                problems.append(
                    (
                        r.label,
                        f"its application transaction(s) {', '.join(missing)} are missing from "
                        "the table's log (a commit file was edited): adding its log again would "
                        "not be refused, and would count its events twice",
                    )
                )
        return problems


def _writes(lines: Sequence[str]) -> bool:
    """Whether a commit file's ``commitInfo`` says it is a write (every commit of this module
    that adds, removes or records: ``create_write_transaction``), not a commit that holds no
    action by design (delta-rs's ``VACUUM START`` / ``VACUUM END``)."""
    for line in lines:
        if line.startswith('{"commitInfo"'):
            with suppress(ValueError, TypeError, KeyError, AttributeError):
                return bool(json.loads(line)["commitInfo"].get("operation") == "WRITE")
            return False
    return False


def _tally(records: pa.Table, store: Store) -> tuple[dict[str, int], list[str]]:
    """What ``_run`` rows (``robot``, ``run`` and their ``rows`` JSON) add up to per
    partition (derived partitions only when every run records them), each distinct ``rows``
    parsed once; and the runs recorded more than once (``robot/run``). Raises ValueError or
    TypeError for a ``rows`` that is no record's."""
    recorded: dict[str, int] = {t: 0 for t in store.registry.types}
    recorded[RUN_TYPE] = records.num_rows
    docs = []
    for item in pc.value_counts(records.column("rows").combine_chunks()).to_pylist():
        doc = json.loads(item["values"])
        if not isinstance(doc, dict) or not all(type(n) is int for n in doc.values()):
            raise ValueError(f"rows {item['values']!r}")
        docs.append((doc, int(item["counts"])))
    every = all(any(k.startswith(_DERIVED_PREFIX) for k in doc) for doc, _ in docs)
    for doc, count in docs:
        for kind, n in doc.items():
            if every or not kind.startswith(_DERIVED_PREFIX):
                recorded[kind] = recorded.get(kind, 0) + n * count
    per_run = records.group_by(["robot", "run"]).aggregate([([], "count_all")])
    twice = [
        f"{robot}/{run}"
        for robot, run, n in zip(*per_run.to_pydict().values(), strict=True)
        if n > 1
    ]
    return recorded, sorted(twice)


def _count_problems(
    files: Sequence[DataFile],
    recorded: Mapping[str, int],
    unreadable: Sequence[tuple[DataFile, str]],
) -> list[str]:
    """Partitions whose rows, by the table's log, are not what the runs' records add up to
    (with ``_run`` files that cannot be read: only fewer rows than the readable records name
    is wrong, and their own rows count as recorded)."""
    held: dict[str, int] = {}
    unknown: set[str] = set()
    for f in files:
        if f.rows is None:
            unknown.add(f.kind)
        else:
            held[f.kind] = held.get(f.kind, 0) + f.rows
    recorded = {**recorded, RUN_TYPE: recorded[RUN_TYPE] + sum(f.rows or 0 for f, _ in unreadable)}
    problems = []
    for kind in sorted(recorded):
        got, want = held.get(kind, 0), recorded[kind]
        if kind in unknown or got == want or (unreadable and got > want):
            continue
        if got < want:
            why = f"{want - got} row(s) the runs recorded are in no data file of the log"
        else:
            why = f"{got - want} row(s) no run's record names"
        problems.append(f"type={kind} holds {got} rows, the runs recorded {want} ({why})")
    return problems


def _run_problems(
    runs: Sequence[TableRun],
    held: Mapping[tuple[str, str, str, str], int],
    damaged_kinds: set[str],
    unreadable: bool,
) -> list[tuple[str, str]]:
    """Each run whose rows of a type in the table (``held``: by robot, run, commit, type) are
    not what its ``_run`` row records, and rows of a commit no ``_run`` row records (not with
    ``unreadable`` records: they may be those runs'). A type with a damaged file is left to
    that file's report."""
    problems = []
    commits = {(r.robot, r.run, r.commit) for r in runs}
    for r in runs:
        want = {**r.rows, **r.derived_rows, RUN_TYPE: 1}
        for kind in sorted(want):
            got = held.get((r.robot, r.run, r.commit, kind), 0)
            if got != want[kind] and kind not in damaged_kinds:
                problems.append(
                    (
                        r.label,
                        f"type={kind}: {got} row(s) in the table, its `_run` row records "
                        f"{want[kind]} (a data file's `add` is missing from the table's log)",
                    )
                )
    if not unreadable:
        kinds_recorded = {k for r in runs for k in (*r.rows, *r.derived_rows, RUN_TYPE)}
        unrecorded: dict[tuple[str, str, str], dict[str, int]] = {}
        for (robot, run, commit, kind), n in sorted(held.items()):
            if (robot, run, commit) in commits or kind in damaged_kinds:
                continue
            if kind in kinds_recorded or not kind.startswith((_DERIVED_PREFIX, "_")):
                unrecorded.setdefault((robot, run, commit), {})[kind] = n
        for (robot, run, commit), kinds in unrecorded.items():
            problems.append(
                (
                    f"{robot}/{run}",
                    f"{sum(kinds.values())} row(s) of {len(kinds)} type(s) "
                    f"({', '.join(sorted(kinds))}) of commit {commit[:16]}… that no `_run` row "
                    "records (its `_run` file's `add` is missing from the table's log)",
                )
            )
    return problems
