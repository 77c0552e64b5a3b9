"""Write the product's payload schema files from its records: ``make schemas``.

The records in :mod:`objsearch.agent.catalogue` are the one definition of every payload the
agent writes; ``events/schema/<type>.v<version>.json`` is written from them by
:mod:`objsearch.events.schema_writer` and never edited by hand. An older version is its released
file, kept byte for byte (and read by an upcast step, :mod:`objsearch.agent.upcasters`). After changing a record (or adding
a version), run::

    python -m objsearch.agent.schema_files          # writes the checkout's events/schema/
    python -m objsearch.agent.schema_files --check  # exit 1 and name the files that are stale

``tests/events/test_schemas.py`` fails while a committed file differs from what this writes.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from objsearch.agent.catalogue import CATALOGUE
from objsearch.events import schema_writer


def default_folder() -> Path:
    """The catalogue's schema folder, if it is a folder of a checkout (not an installed wheel)."""
    folder = CATALOGUE.schemas
    if not isinstance(folder, Path) or "site-packages" in folder.parts:
        raise SystemExit(
            f"the schema folder {folder} is not a checkout's: give the folder to write to"
        )
    return folder


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m objsearch.agent.schema_files",
        description="write events/schema/*.json from the catalogue's records",
    )
    parser.add_argument(
        "folder", nargs="?", type=Path, help="default: the checkout's events/schema"
    )
    parser.add_argument(
        "--check", action="store_true", help="write nothing; exit 1 if a file is stale"
    )
    args = parser.parse_args(argv)
    folder: Path = args.folder or default_folder()
    if args.check:
        stale = schema_writer.differences(CATALOGUE, folder)
        for line in stale:
            print(line, file=sys.stderr)
        return 1 if stale else 0
    folder.mkdir(parents=True, exist_ok=True)
    changed = schema_writer.write(CATALOGUE, folder)
    total = len(schema_writer.render(CATALOGUE))
    print(f"{len(changed)} of {total} schema files changed in {folder}")
    for name in changed:
        print(f"  {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
