"""File-system steps whose order is what makes the log crash-safe."""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import stat
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable

#: Called after every durable step when set; production never sets it. The kill tests
#: (:mod:`objsearch.testing.killtest`) install a counter that SIGKILLs the process at its N-th
#: step, so no environment variable is read on the write path.
_observer: Callable[[], None] | None = None


def observe_durable_steps(observer: Callable[[], None] | None) -> None:
    """Call ``observer`` after each durable step (an fsync or a rename made through this module,
    or a :func:`durable_step`) from now on; ``None`` removes it. One observer per process."""
    global _observer
    _observer = observer


def _step() -> None:
    if _observer is not None:
        _observer()


def durable_step() -> None:
    """A durable step made outside this module (a Delta commit delta-rs wrote, an object put
    on a bucket): counted as one, so the kill tests kill right after it too."""
    _step()


def fsync_dir(directory: Path, *, step: bool = True) -> None:
    """Make a directory's entries (new files, renames) durable, not only the files' contents.
    ``step=False`` when it directly follows a step that changed nothing a reader could see
    since: a kill after it would leave what a kill after that step leaves (a kill test kills the
    process, not the machine), so counting it would only repeat that case."""
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    if step:
        _step()


def fsync_file(path: Path) -> None:
    """Make a file's contents durable."""
    fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    _step()


def rename(source: Path, target: Path) -> None:
    """``os.rename`` (atomic, fails on an existing non-empty directory); a kill-test step.
    Durable once the parents of both are fsync'ed."""
    os.rename(source, target)
    _step()


def make_dirs(directory: Path) -> None:
    """``mkdir -p`` that also makes each new directory's entry in its parent durable."""
    missing: list[Path] = []
    probe = directory
    while not probe.exists():
        missing.append(probe)
        probe = probe.parent
    directory.mkdir(parents=True, exist_ok=True)
    for created in reversed(missing):
        fsync_dir(created.parent)


def write_atomic(path: Path, data: bytes) -> None:
    """Replace ``path`` with ``data`` so a crash or an error leaves either the old file or the new
    one, never a truncated one, and the new one is durable when this returns.

    The one atomic write of the project (the log's metadata, snapshots, lake manifests, the data
    build's files). The temporary file is hidden and named per process, so two writers never share
    one, and it is removed if anything fails. Permissions are left to the umask, as ``open()``
    would. The parent folder must exist (:func:`make_dirs` creates it durably).
    """
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_CLOEXEC, 0o666)
        try:
            write_all(fd, data)
            os.fsync(fd)
        finally:
            os.close(fd)
        _step()
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _step()
    fsync_dir(path.parent)


def try_lock(path: Path) -> int | None:
    """Take an exclusive, non-blocking ``flock`` on ``path`` (created if needed).

    Returns the locked descriptor (closing it releases the lock, as does the process dying), or
    None if someone else holds it. The lock file is never deleted: unlinking a lock file lets two
    processes lock two different inodes of the same name.
    """
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
    if not _flock_or_close(fd):
        return None
    # The holder's pid is only a hint for the "locked" error message.
    with contextlib.suppress(OSError):
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
    return fd


def flock_nb(fd: int) -> bool:
    """Take an exclusive, non-blocking ``flock`` on ``fd``; False if someone else holds it."""
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


def _flock_or_close(fd: int) -> bool:
    # The descriptor is closed unless the lock was taken, whatever goes wrong.
    try:
        locked = flock_nb(fd)
    except BaseException:
        os.close(fd)
        raise
    if not locked:
        os.close(fd)
    return locked


def lock_holder_hint(path: Path) -> str:
    """``" by pid N"`` if the lock file names its holder, else ``""``."""
    try:
        pid = path.read_text(encoding="ascii").strip()
    except (OSError, ValueError):
        return ""
    return f" by pid {pid}" if pid.isdigit() else ""


def is_locked(path: Path) -> bool:
    """Whether another open file description holds ``path``'s lock, without taking it for long.

    Read-only: a missing lock file means nobody ever wrote there, and nothing is created.
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    except FileNotFoundError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    else:
        fcntl.flock(fd, fcntl.LOCK_UN)
        return False
    finally:
        os.close(fd)


def try_lock_dir(directory: Path) -> int | None:
    """Take an exclusive, non-blocking ``flock`` on a directory itself.

    Returns the locked descriptor (closing it, or the process dying, releases the lock), or None
    if someone else holds it. A directory cannot be unlinked from under its holder while it has
    entries, unlike a lock file, so a careless ``rm`` cannot let a second writer in.
    """
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    if not _flock_or_close(fd):
        return None
    return fd


def write_all(fd: int, data: bytes) -> None:
    """``os.write`` until every byte is written (a write may be short)."""
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view) :]


def write_new(path: Path, data: bytes) -> None:
    """Create ``path`` (never replacing a file) with ``data``, durably: file and folder fsync'ed."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o644)
    try:
        write_all(fd, data)
        os.fsync(fd)
    finally:
        os.close(fd)
    fsync_dir(path.parent)


class NotARegularFileError(OSError):
    """A path that :func:`read_regular` will not read: a link, a FIFO, a device, a folder, a
    socket, or a file past the size bound."""


def describe_mode(mode: int) -> str:
    """What a file of this ``st_mode`` is, in words (``a FIFO``, ``a symbolic link``, …)."""
    kinds = (
        (stat.S_ISLNK, "a symbolic link"),
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    )
    return next((name for test, name in kinds if test(mode)), "not a regular file")


def read_regular(path: Path, max_bytes: int) -> bytes:
    """The bytes of ``path`` if it is a regular file of at most ``max_bytes``, read without
    following a link and without blocking on a FIFO (``O_NOFOLLOW | O_NONBLOCK``, then
    ``fstat`` of what was opened).

    Raises :class:`FileNotFoundError` if nothing is there, :class:`NotARegularFileError` naming
    what is there instead (or the size) for anything else, and other :class:`OSError` as the
    system reports them. A device or a FIFO is never opened (``lstat`` first), so neither its
    side effects nor an endless read can happen; one swapped in after that is caught by the
    ``fstat`` of the descriptor."""
    st = os.lstat(path)
    if not stat.S_ISREG(st.st_mode):
        raise NotARegularFileError(
            errno.EINVAL, f"{describe_mode(st.st_mode)}, not a regular file", str(path)
        )
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as exc:
        if exc.errno == errno.ELOOP:  # replaced by a link since the lstat
            raise NotARegularFileError(
                errno.ELOOP, "a symbolic link, not a regular file", str(path)
            ) from None
        raise
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise NotARegularFileError(
                errno.EINVAL, f"{describe_mode(st.st_mode)}, not a regular file", str(path)
            )
        if st.st_size > max_bytes:
            raise NotARegularFileError(
                errno.EFBIG, f"{st.st_size:,} bytes, past the bound of {max_bytes:,}", str(path)
            )
        chunks: list[bytes] = []
        held = 0
        while chunk := os.read(fd, min(1 << 20, max_bytes + 1 - held)):
            chunks.append(chunk)
            held += len(chunk)
            if held > max_bytes:  # grew since the fstat
                raise NotARegularFileError(
                    errno.EFBIG, f"more than the bound of {max_bytes:,} bytes", str(path)
                )
        return b"".join(chunks)
    finally:
        os.close(fd)
