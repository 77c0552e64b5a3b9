"""Kill-point harness: run a command in a process that SIGKILLs itself after its N-th durable step.

Every fsync and rename made through :mod:`objsearch.events._fs` (the lake's commits, the ingest
report) is a *step*; :func:`kill_after_steps` installs an observer there that SIGKILLs the
process right after its N-th (``python -m devtools.killtest N ARGV...`` runs the
command line so, from a fresh interpreter). A test runs a command with N = 1, 2, … until it completes without dying, so it
is killed once at every step of its commit, not at random moments, and checks each time that a
re-run completes and leaves what an uninterrupted run leaves.

A process start costs more than most commits (imports of pyarrow, DuckDB, …), so
:class:`KillServer` is one Python process that has imported the command line once and forks a
fresh child per command: the child installs the counter and calls ``objsearch.cli.main(argv)``,
the real command line, and the server reports how it ended. SIGKILL leaves the page cache alone,
so this tests the order of operations and recovery, not power loss. What every command
builds before its first step (the parser, the store's compiled schemas, the ROS type stores) is
built once in the server, so a child's time is the command's own work; its fsyncs return at once
(the page cache is what a SIGKILL leaves, fsync'ed or not), each still one step.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Final

from objsearch.events import _fs

#: The checkout, which holds ``devtools/`` (a dev-only folder, not installed): the server finds
#: :func:`kill_after_steps` there whatever its working directory.
CHECKOUT: Final = str(Path(__file__).resolve().parents[1])

_SERVER: Final = r"""
import json, os, signal, sys, traceback
sys.path.insert(1, sys.argv[2])  # the checkout (KillServer): devtools/ is not installed
import duckdb, pyarrow.parquet
import objsearch.cli, objsearch.cli_query, objsearch.cli_bags
import objsearch.events.lake, objsearch.pipeline.bags.ingest, objsearch.pipeline.bags.read
import objsearch.replay.analytics, rosbags.highlevel, tqdm
import numpy.ma  # imported on first use by np.unique (a bag's pose tracks)
import objsearch.product  # the relation models lake add folds with (the agent's strategies)
from devtools.killtest import kill_after_steps
from objsearch.agent.catalogue import STORE
from objsearch.ros.types import Distro, typestore
# Built here once rather than in every child (each is most of a short command's CPU): the
# parser and the command modules it imports, the store's schemas and upcasters, the ROS types.
parser = objsearch.cli.build_parser()
STORE.upcaster
for distro in Distro:
    typestore(distro)
# A SIGKILL leaves the page cache, so whether a page reached the disk is invisible here: the
# children's fsyncs return at once (each is still a step; the steps are counted after it). On a
# disk other jobs write to, an fsync took 4-11 ms, and an ingest makes 33 of them.
os.fsync = lambda fd: None
exec(sys.argv[1])  # the test's prelude (KillServer(prelude=))
for line in sys.stdin:
    job = json.loads(line)
    pid = os.fork()
    if pid == 0:
        fd = os.open(job["output"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        if job["kill_after"]:
            kill_after_steps(job["kill_after"])
        code = 70
        try:
            code = objsearch.cli.main(job["argv"], parser=parser)
        except BaseException:
            traceback.print_exc()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    _, status = os.waitpid(pid, 0)
    code = -os.WTERMSIG(status) if os.WIFSIGNALED(status) else os.WEXITSTATUS(status)
    sys.stdout.write(f"{code}\n")
    sys.stdout.flush()
"""


def kill_after_steps(n: int) -> None:
    """SIGKILL this process right after its ``n``-th durable step from now (``n`` >= 1)."""
    if n < 1:
        raise ValueError(f"kill_after_steps: n must be >= 1, not {n}")
    steps = 0

    def count() -> None:
        nonlocal steps
        steps += 1
        if steps == n:
            os.kill(os.getpid(), signal.SIGKILL)

    _fs.observe_durable_steps(count)


@dataclass(frozen=True, slots=True)
class KillOutcome:
    code: int  # exit status, or minus the signal that ended it
    output: str  # stdout and stderr together

    @property
    def killed(self) -> bool:
        return self.code == -9


class KillServer:
    """Runs ``objsearch`` commands in forked children; a context manager."""

    def __init__(self, scratch: Path, *, prelude: str = "") -> None:
        """``prelude``: Python the server runs once before it forks any child (e.g. a
        threshold lowered so a small lake reaches the step a test kills at)."""
        self._output = scratch / "killtest-output.txt"
        self._server = subprocess.Popen(
            [sys.executable, "-c", _SERVER, prelude, CHECKOUT],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            bufsize=1,
        )

    def run(self, argv: list[str], *, kill_after: int = 0) -> KillOutcome:
        """Run ``objsearch ARGV`` in a fresh child, killed after step ``kill_after`` (0: never)."""
        assert self._server.stdin is not None and self._server.stdout is not None
        job = {
            "argv": argv,
            "kill_after": kill_after,
            "output": str(self._output),
        }
        self._server.stdin.write(json.dumps(job) + "\n")
        self._server.stdin.flush()
        line = self._server.stdout.readline()
        if not line:
            raise RuntimeError("the kill-test server died")
        return KillOutcome(int(line), self._output.read_text(encoding="utf-8", errors="replace"))

    def close(self) -> None:
        if self._server.stdin is not None:
            self._server.stdin.close()
        self._server.wait(timeout=30)

    def __enter__(self) -> KillServer:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def tree(root: Path, *, ignore: frozenset[str] = frozenset({".writer"})) -> dict[str, bytes | None]:
    """Every file (its bytes) and folder (None) under ``root`` by relative path: what a lake
    holds, to compare an interrupted-then-rerun lake with an uninterrupted one."""
    found: dict[str, bytes | None] = {}
    for path in sorted(root.rglob("*")):
        rel = str(path.relative_to(root))
        if path.name in ignore:
            continue
        found[rel] = None if path.is_dir() else path.read_bytes()
    return found


#: A fleet lake's content as tables (:func:`table_content`): each run's (date, digest, events),
#: and the rows per run and type (``_bag`` records included).
TableContent = tuple[dict[tuple[str, str], tuple[str, str, int]], list[tuple[str, str, str, int]]]


def table_content(root: str | Path) -> TableContent:
    """What readers of the fleet lake at ``root`` see, as tables — to compare an interrupted-
    then-rerun lake with an uninterrupted one (file names and commit tokens differ) — checked
    on the way: no data file the table names is damaged or missing, every row of a run belongs
    to the run's current commit, and no run and no event is there twice."""
    import pyarrow.compute as pc

    from objsearch.agent.catalogue import STORE
    from objsearch.events.lake import TableLake
    from objsearch.pipeline.bags.ledger import BAG_TYPE

    lake = TableLake(root, store=STORE)
    table = lake.table()
    good, bad = lake.scan(table)
    if bad:
        raise AssertionError(f"damaged files in the table: {bad}")
    runs = lake.runs(table)
    commits = {(r.robot, r.run): r.commit for r in runs}
    if len(commits) != len(runs):
        raise AssertionError(f"a run is there twice: {sorted((r.robot, r.run) for r in runs)}")
    rows = lake.files_dataset(good).to_table(columns=["type", "robot", "run", "commit", "event_id"])
    kind = rows["type"]
    in_runs = rows.filter(pc.not_equal(kind, BAG_TYPE)).select(["robot", "run", "commit"])
    for row in in_runs.group_by(["robot", "run", "commit"]).aggregate([]).to_pylist():
        if commits.get((row["robot"], row["run"])) != row["commit"]:
            raise AssertionError(f"rows of no current commit: {row}")
    events = rows.filter(
        pc.invert(pc.or_(pc.starts_with(kind, "_"), pc.starts_with(kind, "derived.")))
    )
    if events.group_by(["robot", "run", "event_id"]).aggregate([]).num_rows != events.num_rows:
        raise AssertionError("an event is there twice")
    counts = rows.group_by(["robot", "run", "type"]).aggregate([([], "count_all")])
    per_type = sorted(
        (str(r["robot"]), str(r["run"]), str(r["type"]), int(r["count_all"]))
        for r in counts.to_pylist()
    )
    return {(r.robot, r.run): (r.date, r.digest, r.events) for r in runs}, per_type


def main(argv: list[str] | None = None) -> int:
    """``python -m devtools.killtest N ARGV...``: ``objsearch ARGV`` in this fresh
    interpreter, SIGKILLed right after its N-th durable step (the real start-up path, which
    :class:`KillServer`'s forked children skip)."""
    args = sys.argv[1:] if argv is None else argv
    if not args or not args[0].isdigit() or int(args[0]) < 1:
        print("usage: python -m devtools.killtest N ARGV...  (N >= 1)", file=sys.stderr)
        return 2
    kill_after_steps(int(args[0]))
    from objsearch import cli

    return cli.main(args[1:])


__all__ = [
    "KillOutcome",
    "KillServer",
    "TableContent",
    "kill_after_steps",
    "main",
    "table_content",
    "tree",
]

if __name__ == "__main__":
    raise SystemExit(main())
