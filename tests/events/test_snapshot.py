"""The JSON snapshot file beyond the snapshot contract (``tests/events/contract/``): a snapshot
edited by hand and re-checksummed is still not believed."""

from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
import threading
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.agent.scene_graph import SceneGraphProjection
from objsearch.events import fold, read_log
from objsearch.events.snapshot import (
    MAX_SNAPSHOT_BYTES,
    Restored,
    restore,
    save_snapshot,
    snapshot_path,
)

V1_LOG = Path(__file__).parent / "fixtures" / "v1-log"


@pytest.fixture
def log(tmp_path: Path) -> Path:
    shutil.copytree(V1_LOG, tmp_path / "log")
    return tmp_path / "log"


def _restore(log: Path, snaps: Path) -> tuple[SceneGraphProjection, Restored]:
    return restore(
        log,
        SceneGraphProjection,
        SceneGraphProjection.from_snapshot,
        snapshot_dir=snaps,
        store=STORE,
    )


def full(log: Path) -> SceneGraphProjection:
    return fold(read_log(log, store=STORE), SceneGraphProjection())


def _resealed(path: Path, edit: Callable[[dict[str, Any]], None]) -> None:
    """Edit a snapshot's document and recompute its own CRC-32, as a careful hand would."""
    doc = json.loads(path.read_bytes())
    del doc["crc32"]
    edit(doc)
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"))
    path.write_text(text[:-1] + f',"crc32":"{zlib.crc32(text.encode()):08x}"}}\n')


def test_a_snapshot_edited_and_rechecksummed_is_not_believed(
    log: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    snaps = tmp_path / "snaps"
    save_snapshot(snaps, full(log), log=log, store=STORE)
    assert _restore(log, snaps)[1].rejected is None

    def bump(doc: dict[str, Any]) -> None:
        doc["state"]["tasks_folded"] += 1

    _resealed(snapshot_path(snaps, "scene_graph"), bump)
    caplog.clear()
    graph, how = _restore(log, snaps)
    assert how.from_snapshot_seq == 0 and "attested" in str(how.rejected)
    assert graph.tasks_folded == full(log).tasks_folded  # the log's fold, not the edit
    assert [r.levelname for r in caplog.records] == ["WARNING"]  # one line says so


def _restore_in_thread(log: Path, snaps: Path) -> tuple[SceneGraphProjection, Restored] | None:
    """:func:`_restore` in a thread, or None if it has not returned within a minute (a hang: the
    test fails instead of hanging; the restore of this log takes well under a second). What it
    raises is raised here."""
    done: list[tuple[SceneGraphProjection, Restored] | BaseException] = []

    def run() -> None:
        try:
            done.append(_restore(log, snaps))
        except BaseException as exc:
            done.append(exc)

    worker = threading.Thread(target=run, daemon=True)
    worker.start()
    worker.join(60)
    if not done:
        return None
    if isinstance(done[0], BaseException):
        raise done[0]
    return done[0]


def _spoil(kind: str, path: Path, tmp_path: Path) -> None:
    """Put ``kind`` at the snapshot's ``path`` (its trusted file is there before)."""
    if kind == "fifo":
        path.unlink()
        os.mkfifo(path)
    elif kind == "folder":
        path.unlink()
        path.mkdir()
        (path / "inside").write_text("x")
    elif kind == "device":  # /dev/null's numbers: reading it gives nothing, writing loses it
        path.unlink()
        os.mknod(path, 0o600 | stat.S_IFCHR, os.makedev(1, 3))
    elif kind == "link to the snapshot":  # the trusted file itself, behind a link
        path.rename(tmp_path / "elsewhere.json")
        path.symlink_to(tmp_path / "elsewhere.json")
    elif kind == "too large":  # sparse: no disk, but past the bound before a byte is read
        with path.open("r+b") as fh:
            fh.truncate(MAX_SNAPSHOT_BYTES + 1)
    else:
        raise AssertionError(kind)


ODD = {
    "fifo": "a FIFO, not a regular file",
    "folder": "a folder, not a regular file",
    "device": "a character device, not a regular file",
    "link to the snapshot": "a symbolic link, not a regular file",
    "too large": f"{MAX_SNAPSHOT_BYTES + 1:,} bytes, past the bound of {MAX_SNAPSHOT_BYTES:,}",
}


@pytest.mark.parametrize("kind", ODD, ids=list(ODD))
def test_anything_but_a_regular_file_is_a_logged_rebuild(
    log: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture, kind: str
) -> None:
    """A snapshot is a cache: what is at its path is never followed, opened if not a regular
    file, or read past its bound; the projection is the log's fold, with the reason logged."""
    if kind == "device" and os.geteuid() != 0:
        pytest.skip("making a device node needs root")
    snaps = tmp_path / "snaps"
    save_snapshot(snaps, full(log), log=log, store=STORE)
    path = snapshot_path(snaps, "scene_graph")
    _spoil(kind, path, tmp_path)
    caplog.clear()
    restored = _restore_in_thread(log, snaps)
    if restored is None and kind == "fifo":
        # Unblock the hung open (a writer comes and goes) so the thread ends with the test.
        fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
        os.close(fd)
    assert restored is not None, "restore hung"
    graph, how = restored
    assert how.from_snapshot_seq == 0 and how.folded == full(log).last_seq
    assert how.rejected == f"it cannot be read: {ODD[kind]}"
    assert graph.relations == full(log).relations
    # one line says why; for a folder a second that no fresh snapshot could replace it
    assert [r.levelname for r in caplog.records] == ["WARNING"] * (1 + (kind == "folder"))
    assert ODD[kind] in caplog.records[0].getMessage()
    if kind == "link to the snapshot":
        assert (tmp_path / "elsewhere.json").is_file()  # the link's target is left alone
    # Saving a fresh snapshot replaces the odd entry (a folder stays: logged, not raised).
    if kind == "folder":
        assert path.is_dir() and "not saved" in caplog.text
    else:
        assert path.is_file() and not path.is_symlink()
        assert _restore(log, snaps)[1].rejected is None


_READ_DEV_ZERO = """
import resource, sys
from pathlib import Path
resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))
from objsearch.agent.catalogue import STORE
from objsearch.agent.scene_graph import SceneGraphProjection
from objsearch.events.snapshot import restore
graph, how = restore(Path(sys.argv[1]), SceneGraphProjection, SceneGraphProjection.from_snapshot,
                     snapshot_dir=Path(sys.argv[2]), save=False, store=STORE)
print(how.from_snapshot_seq, how.folded, how.rejected)
"""


def test_a_link_to_dev_zero_is_not_read(log: Path, tmp_path: Path) -> None:
    """An endless file behind a link: read in a child process whose address space is bounded
    (3 GiB), so reading it would end in a MemoryError there, not exhaust the machine."""
    snaps = tmp_path / "snaps"
    snaps.mkdir()
    snapshot_path(snaps, "scene_graph").symlink_to("/dev/zero")
    proc = subprocess.run(
        [sys.executable, "-c", _READ_DEV_ZERO, str(log), str(snaps)],
        capture_output=True,
        text=True,
        timeout=600,  # only a guard against a hang, not a speed target
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.split(" ", 2) == [
        "0",
        str(full(log).last_seq),
        "it cannot be read: a symbolic link, not a regular file\n",
    ]
