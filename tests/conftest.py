"""Fixtures every test package may use: the raw shared data (``../shared/data`` beside the clone,
or ``$OBJSEARCH_SHARED``), which the data converter and the FloorPlan-set benches build homes from,
torch on one thread for the modules that fuse maps in the test process, one local S3 server
(moto's) for every test of the fleet lake on a bucket, the fleet lake's verification cache
in a folder of the run's own, and how pytest-xdist shares the tests between its workers."""

from __future__ import annotations

import os
import re
import sys
import uuid
from collections.abc import Generator, Iterator
from pathlib import Path
from typing import Any

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]


def _shared_data() -> Path | None:
    env = os.environ.get("OBJSEARCH_SHARED")
    candidates = [Path(env), Path(env) / "data"] if env else []
    candidates.append(REPO_ROOT.parent / "shared" / "data")
    for path in candidates:
        if (path / "ai2thor" / "ithor_scenes").is_dir():
            return path
    return None


@pytest.fixture(scope="session", autouse=True)
def verification_cache(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The fleet lake's verification cache (``$OBJSEARCH_CACHE``) in a folder of the run's
    own, for this process and every process a test starts: no test writes into the real home."""
    folder = tmp_path_factory.mktemp("objsearch-cache")
    before = os.environ.get("OBJSEARCH_CACHE")
    os.environ["OBJSEARCH_CACHE"] = str(folder)
    yield folder
    if before is None:
        del os.environ["OBJSEARCH_CACHE"]
    else:
        os.environ["OBJSEARCH_CACHE"] = before


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The raw shared data; CI always has it beside the clone."""
    path = _shared_data()
    if path is None:
        pytest.skip(
            "raw shared data not found: set OBJSEARCH_SHARED or provide ../shared/data next to "
            "the repository"
        )
    return path


@pytest.fixture(scope="module")
def one_torch_thread() -> Iterator[None]:
    """Fuse on one thread, as ``objsearch map build`` does by default (``--threads 1``): with two
    OpenMP threads on a 2-core machine that other processes share, torch waits on its thread
    barrier (tests/agent/test_mapping.py's paper-home map: 47 s with two threads at load 7, 8 s
    with one). Imported here, not above: most tests never load torch."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="session")
def s3_server() -> Iterator[dict[str, str]]:
    """moto's S3 server on a free loopback port, started once for the whole run (each start
    costs seconds on a loaded machine); yields the ``AWS_*`` settings that point a client at it.
    A test sets them with ``monkeypatch`` (or takes :func:`bucket`)."""
    from devtools.s3server import s3_server as local_s3_server

    with local_s3_server() as settings:
        yield settings


@pytest.fixture
def bucket(
    s3_server: dict[str, str], monkeypatch: pytest.MonkeyPatch, request: pytest.FixtureRequest
) -> str:
    """A bucket of this test's own on the S3 server (its AWS_* settings in the environment),
    as ``s3://<bucket>/lake``."""
    import boto3

    for name, value in s3_server.items():
        monkeypatch.setenv(name, value)
    readable = re.sub(r"[^a-z0-9-]+", "-", request.node.name.lower()).strip("-")[:40]
    name = f"{readable}-{uuid.uuid4().hex[:8]}"
    boto3.client("s3").create_bucket(Bucket=name)
    return f"s3://{name}/lake"


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config: pytest.Config) -> None:
    """rclpy needs the ROS 2 wheels' libraries on LD_LIBRARY_PATH from its process's start
    (runtime/ros2_env.py; the venv's Python processes no longer all start twice for it): the
    run starts again once with them, before any test, and xdist's workers and every process a
    test starts inherit them."""
    if hasattr(config, "workerinput"):
        return
    from objsearch.runtime import ros2_env

    if ros2_env.ready() or not ros2_env.library_dirs():
        return
    capture = config.pluginmanager.getplugin("capturemanager")
    if capture is not None:
        capture.stop_global_capturing()  # the restarted run's output goes where this one's went
    ros2_env.reexec()


@pytest.hookimpl(wrapper=True)
def pytest_collection(session: pytest.Session) -> Generator[None, object, object]:
    """pytest keeps a test module's assert-rewritten bytecode beside it (``__pycache__``) unless
    the interpreter may not write bytecode, and PYTHONDONTWRITEBYTECODE is set on our machines:
    so every run, in each xdist worker, rewrote every test module and the hypothesis package
    again, half of a worker's collection (12.6 -> 6.3 CPU-s with the rewrites kept). While the
    run collects, bytecode may be written, so the next run on this checkout reads them (pytest
    checks each against its source's size and time); the tests run as the variable says."""
    before = sys.dont_write_bytecode
    sys.dont_write_bytecode = False
    try:
        return (yield)
    finally:
        sys.dont_write_bytecode = before


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """Under pytest-xdist (``make test``: ``-n 2 --dist loadscope``) the tests of one scope run
    in one worker, in turn: a scope is a test module, all of tests/runtime is one (DDS domains
    and ports are chosen per process), and so are the modules that share the data build
    (tests/pipeline/conftest.py's ``built``). Scopes are handed out longest expected first
    (devtools/xdist_scopes.py)."""
    from devtools.xdist_scopes import LongestFirst

    return LongestFirst(config, log)
