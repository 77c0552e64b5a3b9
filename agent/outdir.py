"""Output folders a command owns: it replaces what it wrote there and never touches anything else.

A command that writes into ``--out DIR`` claims it with :func:`claim`. The claim writes a manifest
(:data:`MANIFEST`) into the folder naming the command; when the command ends (finished, failed or
interrupted) the manifest lists every file it wrote under the entries it owns. A later run of the
same command replaces exactly those files. A folder that is not empty and has no manifest —
someone's notes, another program's output — is refused, as is one whose owned entries hold files
the manifest does not list; nothing is deleted then.

The earlier run's files are set aside (:data:`HELD`) when the folder is claimed and deleted only
when the new run ends having written something: a run that fails before its first file — an
unknown home, a bad option found late — gives the earlier output back untouched, and a run killed
while they are set aside gets them back at the next claim.
"""

from __future__ import annotations

import contextlib
import fnmatch
import json
import os
import shutil
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import TracebackType

from objsearch.agent.errors import ObjsearchError

MANIFEST = ".objsearch-output.json"
#: Where a claim sets the earlier run's files aside until the new run has written something.
HELD = ".objsearch-previous"
FORMAT = "objsearch.output/1"


class OutputDirError(ObjsearchError):
    """An output folder the command may not write into or clear."""


def _files_under(root: Path, patterns: Sequence[str]) -> Iterator[str]:
    """Relative paths (POSIX) of the files under the entries of ``root`` matching ``patterns``."""
    if not root.is_dir():
        return
    for entry in sorted(root.iterdir()):
        if entry.name in (MANIFEST, HELD) or not any(
            fnmatch.fnmatchcase(entry.name, p) for p in patterns
        ):
            continue
        if entry.is_dir() and not entry.is_symlink():
            for dirpath, dirnames, filenames in os.walk(entry):
                dirnames.sort()
                for name in sorted(filenames):
                    yield (Path(dirpath) / name).relative_to(root).as_posix()
                for name in dirnames:
                    if (Path(dirpath) / name).is_symlink():
                        yield (Path(dirpath) / name).relative_to(root).as_posix()
        else:
            yield entry.name


def _shown(paths: Sequence[str], root: Path) -> str:
    listed = ", ".join(str(root / p) for p in paths[:3])
    return listed + (f" and {len(paths) - 3} more" if len(paths) > 3 else "")


class OutputDir:
    """A claimed output folder; use as a context manager so the manifest is always completed."""

    def __init__(self, path: Path, command: str, owns: Sequence[str]) -> None:
        self.path = path
        self.command = command
        self.owns = tuple(owns)

    def _write_manifest(self, files: Sequence[str], *, complete: bool) -> None:
        doc = {
            "format": FORMAT,
            "command": self.command,
            "owns": list(self.owns),
            "complete": complete,
            "files": sorted(files),
        }
        tmp = self.path / f"{MANIFEST}.tmp"
        tmp.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
        tmp.replace(self.path / MANIFEST)

    def finish(self) -> None:
        """Record every file now under the owned entries as this command's; a run that wrote
        nothing (it failed before its first file) gives the folder back."""
        files = list(_files_under(self.path, self.owns))
        if files:
            self._write_manifest(files, complete=True)
        else:
            (self.path / MANIFEST).unlink(missing_ok=True)

    def __enter__(self) -> OutputDir:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if not self.path.is_dir():
            return
        if not any(True for _ in _files_under(self.path, self.owns)) and _restore(self.path):
            return  # wrote nothing (it failed first): the earlier output comes back as it was
        # Also after a failure or Ctrl-C: what the run wrote is the command's to replace later.
        self.finish()
        shutil.rmtree(self.path / HELD, ignore_errors=True)


def read_manifest(path: Path) -> dict[str, object] | None:
    """The manifest of ``path``, or None when the folder has none (or an unreadable one)."""
    try:
        doc = json.loads((path / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        return None
    return doc


def claim(
    path: Path,
    *,
    command: str,
    owns: Sequence[str],
    force: bool = False,
    replace_needs_force: bool = True,
    option: str = "--out",
) -> OutputDir:
    """Make ``path`` this command's output folder, clearing only what an earlier run of it wrote.

    ``owns`` are the names (glob patterns) of the entries the command writes directly under
    ``path``. With ``replace_needs_force`` an earlier run's output is replaced only with ``force``.
    Raises :class:`OutputDirError` (and deletes nothing) when the folder cannot be claimed.
    """
    if not str(path).strip():
        raise OutputDirError(f"{option} is empty; name the output folder")
    out = OutputDir(path, command, owns)
    if path.exists() and not path.is_dir():
        raise OutputDirError(f"{option} {path} is a file, not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputDirError(f"cannot create {option} {path}: {exc.strerror or exc}") from exc
    _restore(path)  # a run killed while the earlier output was set aside
    entries = [e for e in path.iterdir() if e.name not in (MANIFEST, f"{MANIFEST}.tmp")]
    manifest = read_manifest(path)
    if manifest is None:
        if entries:
            raise OutputDirError(
                f"{path} is not empty and was not written by objsearch {command} "
                f"(it has no {MANIFEST}); choose another {option} or empty it yourself "
                "(nothing was deleted)"
            )
        out._write_manifest([], complete=False)
        return out
    if manifest.get("command") != command:
        raise OutputDirError(
            f"{path} holds the output of objsearch {manifest.get('command')}, not of "
            f"objsearch {command}; choose another {option} (nothing was deleted)"
        )
    recorded = manifest.get("files")
    ours = {f for f in recorded if isinstance(f, str)} if isinstance(recorded, list) else set()
    present = list(_files_under(path, owns))
    if present and replace_needs_force and not force:
        raise OutputDirError(
            f"{path} already holds the output of objsearch {command}; pass --force to replace it"
        )
    unknown = [f for f in present if f not in ours]
    if unknown:
        raise OutputDirError(
            f"{path} holds files objsearch {command} did not write where it writes "
            f"({_shown(unknown, path)}); move them away or choose another {option} "
            "(nothing was deleted)"
        )
    _set_aside(path, present)
    out._write_manifest([], complete=False)
    return out


def _set_aside(root: Path, files: Sequence[str]) -> None:
    """Move ``files`` (relative to ``root``) under :data:`HELD` with the manifest that lists them,
    then remove the folders they leave empty."""
    if not files:
        return
    held = root / HELD
    held.mkdir(exist_ok=True)
    shutil.copyfile(root / MANIFEST, held / MANIFEST)
    folders: set[Path] = set()
    for rel in files:
        target = root / rel
        (held / rel).parent.mkdir(parents=True, exist_ok=True)
        if target.is_symlink() or target.exists():
            target.replace(held / rel)
        folders.update(p for p in target.parents if p != root and root in p.parents)
    for folder in sorted(folders, key=lambda p: len(p.parts), reverse=True):
        with contextlib.suppress(OSError):  # still holds something: left as it is
            folder.rmdir()


def _restore(root: Path) -> bool:
    """Put the files set aside under :data:`HELD` back where they were, with their manifest (a
    file the new run wrote in the meantime is kept and the earlier one dropped); False when
    nothing was set aside."""
    held = root / HELD
    if not held.is_dir():
        return False
    manifest = read_manifest(held)
    for rel in _files_under(held, ("*",)):
        target = root / rel
        if not (target.is_symlink() or target.exists()):
            target.parent.mkdir(parents=True, exist_ok=True)
            (held / rel).replace(target)
    if manifest is not None:
        (held / MANIFEST).replace(root / MANIFEST)
    shutil.rmtree(held, ignore_errors=True)
    return True
