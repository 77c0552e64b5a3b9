"""The fleet lake's verification cache (``events/lake/verified.py``): a content-addressed
data file is hashed once per change of its ``stat`` identity, a cache that cannot be read or
written costs hashing again and nothing else, and nothing of it lives in the lake."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

import objsearch.events.lake.verified as verified
from objsearch.agent.catalogue import STORE
from objsearch.events.lake import TableLake, add_log
from objsearch.events.lake.schema import TABLE_DIR
from objsearch.events.lake.storage import file_sha256
from objsearch.events.lake.verified import VerifiedFiles, cache_dir

from .lake_logs import same_size_rewrite, small_log


@pytest.fixture
def lake(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> TableLake:
    """A fleet lake of one run, its cache in a folder of this test's own, and every file old
    enough to be trusted once hashed (the files were written a moment ago: see
    :data:`~objsearch.events.lake.verified.RACY_NS`, tested on its own below)."""
    monkeypatch.setenv("OBJSEARCH_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(verified, "RACY_NS", 0)
    lake = TableLake(tmp_path / "lake", store=STORE)
    add_log(small_log(tmp_path / "log"), lake, robot="r")
    return lake


def scanned(lake: TableLake) -> tuple[int, list[str]]:
    """Files a fresh reader hashed, and the files it left out."""
    reader = TableLake(lake.root, store=STORE)
    _, bad = reader.scan()
    return reader.hashed, [f.path for f, _ in bad]


def test_every_file_the_lake_writes_is_named_after_its_hash(lake: TableLake) -> None:
    files = lake.data_files()
    assert files and all(file_sha256(f.path) is not None for f in files)
    assert lake.verify().damaged == []


def test_a_file_is_hashed_once_then_found_in_the_cache(lake: TableLake) -> None:
    files = len(lake.data_files())
    assert scanned(lake) == (files, [])  # first sight: every file hashed
    assert scanned(lake) == (0, [])  # then none: one stat a file
    assert cache_dir() == Path(os.environ["OBJSEARCH_CACHE"])
    assert len(list(cache_dir().rglob("*.json"))) == 1


def test_a_file_rewritten_with_the_same_bytes_is_hashed_again_and_kept(lake: TableLake) -> None:
    scanned(lake)
    victim = Path(lake.uri) / lake.data_files()[0].path
    victim.write_bytes(victim.read_bytes())  # a new ctime (and mtime), the same bytes
    assert scanned(lake) == (1, [])
    assert scanned(lake) == (0, [])


def test_a_same_size_rewrite_after_a_query_is_found(lake: TableLake) -> None:
    scanned(lake)  # the cache holds every file now
    victim = next(f for f in lake.data_files() if f.kind == "search_failed")
    same_size_rewrite(Path(lake.uri) / victim.path)
    assert (Path(lake.uri) / victim.path).stat().st_size == victim.size
    assert scanned(lake) == (1, [victim.path])
    assert scanned(lake) == (1, [victim.path])  # a damaged file is never remembered as good


def test_a_garbled_cache_is_an_empty_one(lake: TableLake) -> None:
    files = len(lake.data_files())
    scanned(lake)
    [cache] = cache_dir().rglob("*.json")
    for garbage in (b"{not json", b"\xff\xfe", json.dumps({"format": "other"}).encode()):
        cache.write_bytes(garbage)
        assert scanned(lake) == (files, [])
    doc = json.loads(cache.read_text(encoding="utf-8"))
    doc["files"] = {rel: ["x", 1] for rel in doc["files"]}  # entries of another shape
    cache.write_text(json.dumps(doc), encoding="utf-8")
    assert scanned(lake) == (files, [])
    assert scanned(lake) == (0, [])


def test_a_cache_that_cannot_be_written_costs_hashing_and_nothing_else(
    lake: TableLake, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A folder that cannot be made (a file is in the way; even root cannot make it).
    (tmp_path / "in-the-way").write_text("a file", encoding="utf-8")
    monkeypatch.setenv("OBJSEARCH_CACHE", str(tmp_path / "in-the-way" / "cache"))
    files = len(lake.data_files())
    assert scanned(lake) == (files, [])
    assert scanned(lake) == (files, [])  # nothing remembered, no error


def test_a_file_younger_than_the_clocks_tick_is_hashed_again(
    lake: TableLake, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A hash taken within RACY_NS of the file's last change is not trusted: a rewrite in the
    # same tick of a coarse file-system clock could keep the ctime.
    monkeypatch.setattr(verified, "RACY_NS", 10**18)
    files = len(lake.data_files())
    assert scanned(lake) == (files, [])
    assert scanned(lake) == (files, [])


def test_the_cache_lives_outside_the_lake_and_follows_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("OBJSEARCH_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "objsearch"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_dir() == tmp_path / "home" / ".cache" / "objsearch"
    # one file per lake
    a, b = VerifiedFiles("/lakes/a/events"), VerifiedFiles("/lakes/b/events")
    assert a.path != b.path and a.path.parent == b.path.parent


def test_a_query_writes_nothing_into_the_lake(lake: TableLake) -> None:
    from objsearch.events.sql_limits import close
    from objsearch.replay.analytics import open_analytics, run_query

    def listing() -> dict[str, tuple[int, int]]:
        return {
            str(p.relative_to(Path(lake.root))): (p.stat().st_size, p.stat().st_mtime_ns)
            for p in Path(lake.root).rglob("*")
        }

    before = listing()
    for _ in range(2):  # the cache made, then read
        con = open_analytics(lake.root)
        try:
            assert run_query(con, "SELECT count(*) FROM events")[1][0][0] > 0
        finally:
            close(con)
    assert listing() == before
    assert not list((Path(lake.root) / TABLE_DIR).rglob("*.json.*"))
