"""``lake verify``: every byte of the fleet lake read and checked (:class:`LakeVerify`)."""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterable
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from .checks import LakeChecks, _run_problems
from .schema import RUN_TYPE, DataFile, TableCheck
from .storage import _filesystem, _hash_mismatch


class LakeVerify(LakeChecks):
    """The fleet lake, verified."""

    def verify(
        self, progress: Callable[[list[DataFile]], Iterable[DataFile]] | None = None
    ) -> TableCheck:
        """Read every byte: hash each content-addressed data file in full (whatever the
        verification cache says) and compare with the hash its name records, decode each
        data file in full (page checksums on) and compare its rows with the log's statistics
        (plus the checks of :meth:`scan`); then count each run's rows of each type in the
        decoded files against what its ``_run`` row records (``runs_damaged``: a run short of
        rows — a commit file's ``add`` removed — or rows no run records), and check the log
        (:meth:`_log_problems`) and each run's application transactions. A ``_run`` file that
        does not read is a damaged file like any other; the check goes on without its runs.
        Changes nothing. ``progress`` wraps the files as they are decoded (the CLI's progress
        line)."""

        table = self.table()
        good, bad = self.scan(table, hashes=False)
        size = 0
        checked = 0
        verified: list[DataFile] = []
        #: rows of each (robot, run, commit, type) the decoded files hold
        held: dict[tuple[str, str, str, str], int] = {}
        for f in progress(good) if progress else good:
            try:
                if self.remote:
                    fs, base = _filesystem(self.uri)
                    with fs.open_input_file(f"{base}/{f.path}") as fh:
                        data = fh.read()
                else:
                    data = (Path(self.uri) / f.path).read_bytes()
            except OSError as exc:
                bad.append((f, f"{f.path} cannot be read: {exc}"))
                continue
            mismatch = _hash_mismatch(f, hashlib.sha256(data).hexdigest())
            if mismatch is not None:
                bad.append((f, mismatch))
                continue
            try:
                decoded = pq.ParquetFile(
                    pa.BufferReader(data), page_checksum_verification=True
                ).read()
            except (OSError, pa.ArrowException) as exc:
                bad.append((f, f"{f.path} does not decode: {exc}"))
                continue
            if f.rows is not None and decoded.num_rows != f.rows:
                bad.append(
                    (f, f"{f.path} holds {decoded.num_rows} rows, the table's log records {f.rows}")
                )
                continue
            checked += 1
            size += f.size
            verified.append(f)
            if decoded.num_rows and {"robot", "run", "commit"} <= set(decoded.column_names):
                per_commit = decoded.group_by(["robot", "run", "commit"]).aggregate(
                    [([], "count_all")]
                )
                for robot, run, commit, n in zip(*per_commit.to_pydict().values(), strict=True):
                    key = (robot, run, commit, f.kind)
                    held[key] = held.get(key, 0) + n
        runs, unreadable = self.read_runs(
            table, files=[f for f in verified if f.kind == RUN_TYPE], checked=True
        )
        bad += unreadable
        problems = [("_delta_log", p) for p in self._log_problems(table)]
        problems += [("_delta_log", p) for p in self._empty_commits()]
        damaged_kinds = {f.kind for f, _ in bad}
        problems += _run_problems(runs, held, damaged_kinds, RUN_TYPE in damaged_kinds)
        problems += [(r, p) for r, p in self._transaction_problems(table, runs)]
        return TableCheck(
            files=checked - len(unreadable),
            bytes=size,
            runs=len(runs),
            damaged=[(f.path, why) for f, why in bad],
            runs_damaged=problems,
        )
