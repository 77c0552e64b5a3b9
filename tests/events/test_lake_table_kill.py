"""Kill tests of the fleet lake's commit (``events/lake/commit.py``): ``lake add`` into a fleet
lake — a folder holding the Delta table, and a bucket on moto's S3 server — is killed right after
each of its durable steps (every data file stored under its content-addressed name, fsync'ed
or uploaded; the Delta commit; the
compaction the add then starts: its claim, its commit, the checkpoint; on the bucket, of the
uploads only the first and the last), then run again. At every
kill the lake holds its other runs as they were and the new run either not at all or whole; the
re-run completes and the lake then holds, as tables, what an uninterrupted add leaves (runs,
digests, rows per type), no row twice; the files a killed add left behind belong to no version
of the table (no reader reads them) and ``lake compact`` deletes them.

As :mod:`tests.events.test_lake_kill`: one kill-test server, each command in a forked child."""

from __future__ import annotations

import shutil
from pathlib import Path

import boto3
import pytest

from devtools.killtest import KillServer, table_content
from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake, add_log
from objsearch.events.lake.schema import TABLE_DIR

from .lake_logs import two_type_log

#: Each sweep runs ``lake add`` twice per step: tens of seconds.
pytestmark = pytest.mark.slow


@pytest.fixture(params=["folder", "bucket"])
def place(request: pytest.FixtureRequest, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    """Where the lakes of one test live: a folder, or a bucket of its own on moto's server."""
    if request.param == "folder":
        return str(tmp_path / "lakes")
    settings = request.getfixturevalue("s3_server")
    for name, value in settings.items():
        monkeypatch.setenv(name, value)
    boto3.client("s3").create_bucket(Bucket="kill")
    return "s3://kill"


def _stored(root: str) -> set[str]:
    """The data files under the lake's table (not its log), as paths inside the table."""
    if "://" in root:
        bucket, _, prefix = root.removeprefix("s3://").partition("/")
        table = f"{prefix}/{TABLE_DIR}/"
        pages = boto3.client("s3").get_paginator("list_objects_v2")
        keys = [
            o["Key"]
            for p in pages.paginate(Bucket=bucket, Prefix=table)
            for o in p.get("Contents", [])
        ]
        # data files only: not the empty "folder" markers Arrow's S3 client puts when it moves
        # an object, nor the lake's head record (_objsearch_head.json), as locally
        return {
            k.removeprefix(table)
            for k in keys
            if "/_delta_log/" not in f"/{k}" and k.endswith(".parquet")
        }
    base = Path(root) / TABLE_DIR
    return {
        str(p.relative_to(base))
        for p in base.rglob("*.parquet")
        if "_delta_log" not in p.relative_to(base).parts
    }


def _copy(source: str, target: str) -> None:
    """The whole lake (its log's paths are relative to the table)."""
    if "://" not in source:
        shutil.rmtree(target, ignore_errors=True)
        shutil.copytree(source, target)
        return
    bucket, _, prefix = source.removeprefix("s3://").partition("/")
    to = target.removeprefix(f"s3://{bucket}/")
    s3 = boto3.client("s3")
    for page in s3.get_paginator("list_objects_v2").paginate(Bucket=bucket, Prefix=f"{prefix}/"):
        for obj in page.get("Contents", []):
            key = obj["Key"]
            s3.copy_object(
                Bucket=bucket,
                Key=f"{to}/{key.removeprefix(f'{prefix}/')}",
                CopySource={"Bucket": bucket, "Key": key},
            )


def _remove(root: str) -> None:
    """A lake no longer needed (moto lists a prefix by walking every key of the bucket, and
    every table load lists the log's)."""
    if "://" not in root:
        shutil.rmtree(root)
        return
    bucket, _, prefix = root.removeprefix("s3://").partition("/")
    s3 = boto3.client("s3")
    for page in s3.get_paginator("list_objects_v2").paginate(Bucket=bucket, Prefix=f"{prefix}/"):
        keys = [{"Key": o["Key"]} for o in page.get("Contents", [])]
        if keys:
            s3.delete_objects(Bucket=bucket, Delete={"Objects": keys})


def _table_files(root: str) -> set[str]:
    return {f.path for f in TableLake(root, store=STORE).data_files()}


def test_a_fleet_lake_add_killed_at_every_step_leaves_the_run_out_or_whole(
    place: str, tmp_path: Path
) -> None:
    start = f"{place}/start"
    lake = TableLake(start, store=STORE)
    add_log(two_type_log(tmp_path / "other", stream="run-old"), lake, robot="r")
    before = table_content(start)
    # The add compacts: the table holds more files than this once the run is in.
    files = len(_table_files(start))
    prelude = f"import objsearch.events.lake.rewrite as lr; lr.COMPACT_AT_FILES = {files}"
    log = two_type_log(tmp_path / "log", stream="run-new")
    argv = ["lake", "add", str(log), "--robot", "r", "--lake"]
    with KillServer(tmp_path, prelude=prelude) as server:
        whole = f"{place}/whole"
        _copy(start, whole)
        done = server.run([*argv, whole])
        assert done.code == 0, done.output
        reference = table_content(whole)
        assert set(reference[0]) == {*before[0], ("r", "run-new")}
        assert len(_table_files(whole)) < files  # it compacted

        orphans_deleted = False

        def rerun(root: str, n: int) -> None:
            nonlocal orphans_deleted
            left = _stored(root) - _table_files(root)
            again = server.run([*argv, root])
            assert again.code == 0, f"re-run after a kill at step {n}: {again.output}"
            assert "Traceback" not in again.output
            assert table_content(root) == reference, f"kill at step {n}: the re-run differs"
            if left and not orphans_deleted:
                # What the killed add wrote is no file of the table; compacting deletes it.
                assert not left & _table_files(root)
                TableLake(root, store=STORE).compact(vacuum_hours=0)
                assert _stored(root) == _table_files(root)
                assert table_content(root) == reference
                orphans_deleted = True

        seen: dict[str, list[int]] = {"without": [], "whole": []}
        # Killed before the commit, the lake is the same but for unnamed files, so the re-run
        # is tried from the first and the last such kill; from every kill after the commit.
        pending: tuple[str, int] | None = None
        # The add's first steps write its files, one a type. On the bucket (each child's
        # requests are slow on moto) only the first and the last of those are killed at: they
        # are steps of one kind, each killed at on the folder.
        probe = f"{place}/probe"  # the add's files: added in this process, which never compacts
        _copy(start, probe)
        add_log(log, TableLake(probe, store=STORE), robot="r")
        uploads = len(_table_files(probe)) - files
        _remove(probe)
        # the last step before the commit
        # (a short run's data file is one step: stored whole under its content-addressed name,
        # fsync'ed or uploaded; a large one is streamed and renamed, events/lake/stream_file.py)
        written = uploads
        n = 0
        while True:
            n += 1
            if "://" in place and 1 < n < written:
                n = written
            root = f"{place}/k{n}"
            _copy(start, root)
            outcome = server.run([*argv, root], kill_after=n)
            if not outcome.killed:
                assert outcome.code == 0, outcome.output
                assert table_content(root) == reference
                break
            now = table_content(root)
            others = {k: v for k, v in now[0].items() if k != ("r", "run-new")}
            assert others == before[0], f"kill at step {n}: another run changed"
            if ("r", "run-new") not in now[0]:
                assert now == before, f"kill at step {n}: part of the run is there"
                seen["without"].append(n)
                if n == 1:
                    rerun(root, n)
                    _remove(root)
                else:
                    if pending is not None:
                        _remove(pending[0])
                    pending = (root, n)
                continue
            assert now == reference, f"kill at step {n}: the run is there, but not whole"
            seen["whole"].append(n)
            if pending is not None:
                rerun(*pending)
                _remove(pending[0])
                pending = None
            rerun(root, n)
            _remove(root)
            assert n < 100, "the command never completed"
    # Killed before its commit the run is not there, after it it is, whole. The data files (one
    # a type), the commit, the compaction's claim, its commit and the checkpoint are steps.
    assert pending is None and orphans_deleted
    assert len(seen["without"]) >= 2 and len(seen["whole"]) >= 3, seen
    assert max(seen["without"]) == written and min(seen["whole"]) == written + 1, seen
