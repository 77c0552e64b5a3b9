"""The lake's file digests: every file a commit writes is recorded, checked before it is read,
and a lake written before digests stays readable and can be brought up to them."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events.derived import DERIVED_DIR, derived_tables
from objsearch.events.lake import RUN_FILE, Lake, LakeError, RunInfo, compact_log
from objsearch.events.lake_digest import FILES_KEY, SELF_KEY, file_digest, manifest_digest

from .lake_logs import V1_LOG, small_log


def _flip_in_data_page(path: Path, at: int = 0) -> None:
    """Flip one bit in the first column chunk's pages (between the magic and the footer)."""
    data = bytearray(path.read_bytes())
    footer = len(data) - 8 - int.from_bytes(data[-8:-4], "little")
    where = 4 + (at % (footer - 4))
    data[where] ^= 0x04
    path.write_bytes(bytes(data))


def _as_older_code_wrote_it(info: RunInfo) -> None:
    manifest = info.path / RUN_FILE
    doc = json.loads(manifest.read_bytes())
    del doc[FILES_KEY], doc[SELF_KEY]
    manifest.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n", encoding="utf-8")


@pytest.fixture
def lake(tmp_path: Path) -> tuple[Lake, RunInfo, RunInfo]:
    lake = Lake(tmp_path / "lake", store=STORE)
    a = compact_log(small_log(tmp_path / "a"), lake, robot="r", run="a")
    b = compact_log(small_log(tmp_path / "b", stream="b"), lake, robot="r", run="b")
    return lake, a, b


def test_the_manifest_records_every_file_and_itself(lake: tuple[Lake, RunInfo, RunInfo]) -> None:
    _, a, _ = lake
    on_disk = sorted(
        p.relative_to(a.path).as_posix()
        for p in a.path.rglob("*")
        if p.is_file() and p.name != RUN_FILE
    )
    assert sorted(a.files) == on_disk
    assert {
        f"{d.path(a.path).relative_to(a.path).as_posix()}" for d in derived_tables(STORE)
    } < set(a.files)
    for name, want in a.files.items():
        assert file_digest(a.path / name) == want
    doc = json.loads((a.path / RUN_FILE).read_bytes())
    assert doc[SELF_KEY].startswith("sha256:") and doc[FILES_KEY]["detection.parquet"]["bytes"] > 0


def test_files_are_written_with_page_checksums(lake: tuple[Lake, RunInfo, RunInfo]) -> None:
    _, a, _ = lake
    path = a.path / "detection.parquet"
    pq.ParquetFile(path, page_checksum_verification=True).read()
    _flip_in_data_page(path, at=7)
    with pytest.raises((OSError, pa.ArrowException)):
        pq.ParquetFile(path, page_checksum_verification=True).read()


def test_a_flipped_bit_in_a_page_is_found_and_named(lake: tuple[Lake, RunInfo, RunInfo]) -> None:
    store, a, b = lake
    _flip_in_data_page(a.path / "task_ended.parquet")
    # The cheap check (sizes, ends) cannot see it; the digest check and verify do.
    assert store.scan()[1] == []
    runs, damaged = store.scan(check_digests=True)
    assert runs == [b]
    [bad] = damaged
    assert bad.path == a.path and bad.problems == (
        "task_ended.parquet fails its digest: its bytes are not the ones committed (bit rot, or "
        "the file was changed or swapped after the commit)",
    )
    check = store.verify()
    assert check.damaged == [bad] and check.runs == 2 and check.unverified == []
    assert check.files == len(b.files)
    with pytest.raises(LakeError, match=r"task_ended.parquet: damaged Parquet file: .*digest"):
        store.read_events(a)


def test_a_manifest_that_fails_its_own_digest_is_left_out(
    lake: tuple[Lake, RunInfo, RunInfo],
) -> None:
    store, a, b = lake
    manifest = a.path / RUN_FILE
    manifest.write_bytes(
        manifest.read_bytes().replace(b'"source": "event log', b'"source": "event lug')
    )
    runs, damaged = store.scan()
    assert runs == [b] and "fails its digest" in damaged[0].reason


def test_swapped_run_folders_are_left_out(lake: tuple[Lake, RunInfo, RunInfo]) -> None:
    store, a, b = lake
    a.path.rename(a.path.with_name("tmp"))
    b.path.rename(a.path)
    a.path.with_name("tmp").rename(b.path)
    runs, damaged = store.scan()
    assert runs == [] and all("not this folder" in d.reason for d in damaged)


def test_an_event_table_the_commit_did_not_write_is_refused(
    lake: tuple[Lake, RunInfo, RunInfo],
) -> None:
    store, a, b = lake
    shutil.copy(a.path / "detection.parquet", b.path / "detection_extra.parquet")
    runs, damaged = store.scan()
    assert (
        runs == [a] and "detection_extra.parquet is not in the run's manifest" in damaged[0].reason
    )


def test_a_lake_without_digests_is_read_upgraded_and_then_checked(
    lake: tuple[Lake, RunInfo, RunInfo],
) -> None:
    store, a, b = lake
    for info in (a, b):
        _as_older_code_wrote_it(info)
    old_a = store.find("r", "a")
    assert old_a is not None and old_a.files == {}
    # Readable as before: the cheap checks, every event.
    assert len(store.scan(check_digests=True)[0]) == 2
    assert len(store.read_events(old_a)) == a.events
    check = store.verify()
    assert check.damaged == [] and check.unverified == [a.path, b.path]
    # A run that does not decode is not vouched for by new digests.
    data = (b.path / "moved.parquet").read_bytes()
    (b.path / "moved.parquet").write_bytes(data[:100] + bytes(200) + data[300:])
    assert [r.run for r in store.upgrade()] == ["a"]
    new_a = store.find("r", "a")
    assert new_a is not None and new_a.files == a.files
    assert store.find("r", "b") is not None and store.find("r", "b").files == {}  # type: ignore[union-attr]
    _flip_in_data_page(a.path / "moved.parquet")
    assert [d.path for d in store.verify().damaged] == [a.path, b.path]


def test_committing_the_same_content_again_records_the_digests(tmp_path: Path) -> None:
    store = Lake(tmp_path / "lake", store=STORE)
    first = compact_log(V1_LOG, store, robot="sim")
    _as_older_code_wrote_it(first)
    again = compact_log(V1_LOG, store, robot="sim")
    assert again.files == first.files and again.digest == first.digest


def test_a_derived_table_the_manifest_does_not_list_is_recomputed(
    lake: tuple[Lake, RunInfo, RunInfo],
) -> None:
    # An upgrade killed between writing a derived file and recording it: readers must not
    # trust the file (no digest) and compute its rows from the events; the next upgrade lists it.
    store, a, _ = lake
    spec = derived_tables(STORE)[0]
    manifest = a.path / RUN_FILE
    doc = json.loads(manifest.read_bytes())
    del doc[FILES_KEY][f"{DERIVED_DIR}/{spec.file_name}"]
    doc[SELF_KEY] = manifest_digest(doc)
    manifest.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    info = store.find("r", "a")
    assert info is not None and [d.name for d in info.missing_derived()] == [spec.name]
    assert store.scan(check_digests=True)[1] == []
    assert [r.run for r in store.upgrade()] == ["a"]
    info = store.find("r", "a")
    assert info is not None and info.missing_derived() == [] and info.files == a.files


def test_committing_the_same_content_over_a_damaged_run_restores_it(tmp_path: Path) -> None:
    store = Lake(tmp_path / "lake", store=STORE)
    first = compact_log(V1_LOG, store, robot="sim")
    _flip_in_data_page(first.path / "detection.parquet", at=3)
    (first.path / "moved.parquet").unlink()
    assert [d.path for d in store.verify().damaged] == [first.path]
    again = compact_log(V1_LOG, store, robot="sim")
    assert again == first
    assert store.verify().damaged == []
    assert file_digest(first.path / "detection.parquet") == first.files["detection.parquet"]
