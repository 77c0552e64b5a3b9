"""Which data folder each ``bench homes`` output's homes are read from, for ``bench belief``.

``bench belief`` reads the homes themselves (not only the outputs' rows) for two tables: the days
a ``habit`` target was at its usual place (the schedule drawn again from its seed) and why a
search failed (what the camera shows of the target). Outputs run on different data folders (the
held-out sets each have their own) are pooled by reading each output's homes from the folder it
was run on. For each output, in order, the first of these folders that holds ``homes/<id>.json``:

1. the folder its summary.json records: ``OBJSEARCH_DATA=DIR`` at the head of its ``command``,
   else the ``--out`` of the last of its ``data_build`` commands (a relative path is read from
   the working folder); an output run on the bundled data records none;
2. the ``--data`` folders, in the order given;
3. the data folder of this process (``$OBJSEARCH_DATA``, else the bundled data): what every output
   was read from before outputs could be pooled.

No output records its homes' content (``bench homes`` keeps no logs), so a home file is checked
against the other outputs only: two outputs that name the same home id read from files that
differ byte for byte are refused, never pooled. The folder is handed to the readers as their
``data`` argument (``load_home``, ``habit_schedule``, ``report_homes.failure_cause``), which read
everything of that home from it, the folder's vocabulary and placement statistics too; the
environment is never set, and the readers' caches are keyed by (resolved folder, home id), so a
process that reports on several folders gets each folder's home.
"""

from __future__ import annotations

import json
import shlex
from collections.abc import Mapping, Sequence
from pathlib import Path

from objsearch.agent.datapaths import DATA_ENV, data_dir
from objsearch.agent.errors import ObjsearchError

#: A home id and the data folder its file is read from.
HomeFolders = Mapping[str, Path]


def recorded_data_folder(output: Path) -> Path | None:
    """The data folder an output's summary.json says it was run on (see the module doc), or
    None when it records none."""
    try:
        summary = json.loads((output / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(summary, dict):
        return None
    command = summary.get("command")
    if isinstance(command, str) and command.startswith(f"{DATA_ENV}="):
        words = shlex.split(command)
        return Path(words[0].partition("=")[2])
    builds = summary.get("data_build")
    if isinstance(builds, list) and builds and isinstance(builds[-1], str):
        words = shlex.split(builds[-1])
        if "--out" in words[:-1]:
            return Path(words[words.index("--out") + 1])
    return None


def check_data_folders(folders: Sequence[Path]) -> None:
    """``bench belief --data``: each must be a data folder (one with ``homes/``)."""
    for folder in folders:
        if not (folder / "homes").is_dir():
            raise ObjsearchError(
                f"--data {folder}: not a data folder (no homes/ in it; `objsearch data build "
                "--out DIR` makes one)"
            )


def _looked(output: Path, recorded: Path | None, folders: Sequence[Path], home: str) -> str:
    places = []
    if recorded is None:
        places.append("its summary.json records no data folder")
    elif not recorded.is_dir():
        places.append(f"{recorded} (recorded in its summary.json; no such folder)")
    else:
        places.append(f"{recorded} (recorded in its summary.json)")
    places += [f"{f} (--data)" for f in folders]
    places.append(f"{data_dir()} (${DATA_ENV}, else the bundled data)")
    return (
        f"output {output} ran on home {home!r}, which no data folder holds: looked for "
        f"homes/{home}.json in {'; '.join(places)}; name the folder it was run on with --data DIR"
    )


def home_folders(homes: Mapping[Path, Sequence[str]], extra: Sequence[Path] = ()) -> HomeFolders:
    """Each home id of ``homes`` (output: the home ids of its rows) and the data folder it is read
    from (see the module doc). Raises :class:`ObjsearchError` when a home is in no folder, or
    when two outputs name one home id with files that differ."""
    found: dict[str, tuple[Path, Path, bytes]] = {}  # home: folder, output, content
    for output, names in homes.items():
        recorded = recorded_data_folder(output)
        candidates = [*([recorded] if recorded is not None else []), *extra, data_dir()]
        for home in sorted(set(names)):
            folder = next((f for f in candidates if (f / "homes" / f"{home}.json").is_file()), None)
            if folder is None:
                raise ObjsearchError(_looked(output, recorded, extra, home))
            content = (folder / "homes" / f"{home}.json").read_bytes()
            if home not in found:
                found[home] = (folder, output, content)
            elif found[home][2] != content:
                first, other, _ = found[home]
                raise ObjsearchError(
                    f"outputs {other} and {output} both name home {home!r}, but its files differ "
                    f"({first / 'homes' / home}.json and {folder / 'homes' / home}.json): "
                    "refusing to pool them"
                )
    return {home: folder for home, (folder, _, _) in found.items()}
