"""How every command but the migration opens the lake: :func:`open_lake`, the one place the
retired per-run-folder format (``objsearch.lake/1``) is refused, with the one message that names
its migration command."""

from __future__ import annotations

from pathlib import Path

from ..store import Store
from .common import LakeError
from .fleet import TableLake
from .folder_v1 import LAKE_FORMAT, is_folder_lake
from .table import is_table_lake


class NoLakeError(LakeError):
    """No fleet lake is where a command that reads one was pointed."""


def retired_format_message(root: Path | str) -> str:
    """What every command but ``objsearch lake upgrade`` says of a per-run-folder lake."""
    return (
        f"{root} is a per-run-folder lake ({LAKE_FORMAT}), which this version reads only to "
        f"migrate it: run objsearch lake upgrade --lake {root}"
    )


def open_lake(root_or_uri: Path | str, *, store: Store, existing: bool = False) -> TableLake:
    """The fleet lake at ``root_or_uri`` (a folder or an ``s3://`` URI), read and written with
    ``store`` (the domain's event types, upcasters and derived tables: required, so no lake
    silently derives none of its tables). Raises :class:`LakeError`:

    * for the retired per-run-folder lake, naming the migration command
      (:func:`retired_format_message`); a folder ``lake upgrade`` migrated keeps the damaged
      runs it left in place beside the fleet table, and is a fleet lake;
    * with ``existing`` (a command that reads the lake), :class:`NoLakeError` unless a fleet
      lake is there;
    * without it (a command that may make the lake), for a local place a lake cannot be made
      in: a file, or a folder holding anything but a fleet lake. An object-store URI is not
      looked at: its table is made by the first commit.

    ``objsearch lake upgrade`` is the one command that opens a per-run-folder lake's folder
    with :class:`TableLake` itself (it writes the fleet table beside the old runs)."""
    text = str(root_or_uri)
    remote = "://" in text
    if not remote and is_folder_lake(text) and not is_table_lake(text):
        raise LakeError(retired_format_message(root_or_uri))
    if existing:
        if not is_table_lake(root_or_uri):
            raise NoLakeError(
                f"no lake at {root_or_uri} (add runs with `objsearch lake add LOG --lake "
                f"{root_or_uri}`)"
            )
    elif not remote and not is_table_lake(root_or_uri):
        path = Path(root_or_uri)
        if path.exists() and not path.is_dir():
            raise LakeError(f"{root_or_uri} is a file, not a lake folder")
        if path.is_dir() and any(path.iterdir()):
            raise LakeError(
                f"{root_or_uri} is neither a fleet lake nor empty; give a new or empty folder "
                "for a new lake"
            )
    return TableLake(root_or_uri, store=store)
