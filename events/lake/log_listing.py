"""The fleet lake's current data files read from its table's log, without delta-rs.

``where``, ``replay`` and ``audit`` from a lake run need only what the table's log says of its
files (path, size, rows, partition, the statistics of ``robot`` and ``run``) and of its
application transactions; loading delta-rs for that cost about 30 MB of memory, a third of
such a command's own. :func:`read_listing` reads the log's JSON commit files itself, as the
Delta protocol defines them (each commit's ``add`` and ``remove`` actions, by path, in version
order), and hands back a :class:`LogListing` that answers what those readers ask of a table
(:meth:`~LogListing.get_add_actions`, :meth:`~LogListing.file_uris`,
:meth:`~LogListing.transaction_version`, :meth:`~LogListing.version`).

It reads the log only when that is all the state there is: a local table whose log starts at
version 0 with no checkpoint (a lake never compacted: compaction checkpoints), reader protocol
1, and no action this reader does not know how to apply (a deletion vector, say). Otherwise
it returns None and the caller loads the table with delta-rs, as before. Damage is refused, as
delta-rs refuses it, never read past: a commit file that is not JSON lines of actions (cut,
garbled), a version missing between two others, or no ``protocol``/``metaData`` in the log
raise :class:`TableLakeError`. What a reader checks after the listing is unchanged (the files'
sizes and hashes, each run's rows against its digest).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Final
from urllib.parse import unquote

import pyarrow as pa

from .schema import TableLakeError

#: The actions a commit of this lake (or of delta-rs on its behalf) holds that change nothing a
#: reader of the files needs: the rest (``add``, ``remove``, ``txn``, ``protocol``,
#: ``metaData``) are applied; any other makes :func:`read_listing` hand over to delta-rs.
_INERT: Final = frozenset({"commitInfo", "domainMetadata"})
_ACTIONS: Final = _INERT | {"add", "remove", "txn", "protocol", "metaData"}
#: The columns of :meth:`LogListing.get_add_actions` (those of delta-rs's flattened actions
#: that the lake's readers read).
_COLUMNS: Final = pa.schema(
    [
        ("path", pa.string()),
        ("size_bytes", pa.int64()),
        ("num_records", pa.int64()),
        ("partition.type", pa.string()),
        ("min.robot", pa.string()),
        ("max.robot", pa.string()),
        ("min.run", pa.string()),
        ("max.run", pa.string()),
    ]
)


class LogListing:
    """A table's state at ``version`` as its log's commits leave it: its files (``add``
    actions by path) and its application transactions' versions."""

    def __init__(
        self, uri: str, version: int, files: dict[str, dict[str, Any]], txns: dict[str, int]
    ) -> None:
        self.uri = uri
        self._version = version
        self._files = files
        self._txns = txns

    def version(self) -> int:
        return self._version

    def transaction_version(self, app_id: str) -> int | None:
        return self._txns.get(app_id)

    def get_add_actions(self, flatten: bool = True) -> pa.Table:
        """The files' ``add`` actions as delta-rs's flattened columns (path, size_bytes,
        num_records, partition.type and the statistics of ``robot`` and ``run``)."""
        rows = []
        for path, add in self._files.items():
            stats = _stats(add.get("stats"))
            low, high = stats.get("minValues") or {}, stats.get("maxValues") or {}
            rows.append(
                {
                    "path": path,
                    "size_bytes": add["size"],
                    "num_records": stats.get("numRecords"),
                    "partition.type": (add.get("partitionValues") or {}).get("type"),
                    "min.robot": low.get("robot"),
                    "max.robot": high.get("robot"),
                    "min.run": low.get("run"),
                    "max.run": high.get("run"),
                }
            )
        return pa.Table.from_pylist(rows, schema=_COLUMNS)

    def file_uris(self, file_pruning_predicate: Sequence[tuple[str, str, Any]] = ()) -> list[str]:
        """The files' absolute paths; ``file_pruning_predicate``: ``("type", "in", kinds)``
        terms (the only ones the lake asks), as delta-rs prunes by partition."""
        kinds: set[str] | None = None
        for column, op, value in file_pruning_predicate:
            if (column, op) != ("type", "in"):
                raise ValueError(f"unsupported predicate {(column, op, value)!r}")
            kinds = set(value) if kinds is None else kinds & set(value)
        return [
            str(Path(self.uri) / path)
            for path, add in self._files.items()
            if kinds is None or (add.get("partitionValues") or {}).get("type") in kinds
        ]


def _stats(text: object) -> dict[str, Any]:
    if not isinstance(text, str):
        return {}
    try:
        stats = json.loads(text)
    except ValueError:
        return {}  # statistics a reader cannot use: as if there were none
    return stats if isinstance(stats, dict) else {}


def read_listing(uri: str, root: object) -> LogListing | None:
    """The table at ``uri`` (a local folder) as its log's JSON commits leave it, or None when
    only delta-rs can read it (see the module). Raises :class:`TableLakeError` for a log that
    is damaged (``root``: the lake, for the message)."""
    try:
        return _read_listing(uri, root)
    except _Vanished:
        # A commit file listed a moment ago is gone: a compaction checkpointed the log and
        # cleaned up the commits before it since (or the log is damaged): look again, once.
        try:
            return _read_listing(uri, root)
        except _Vanished as exc:
            raise _damaged(root, str(exc)) from exc


class _Vanished(Exception):
    """A commit file of the listing was not there to read."""


def _read_listing(uri: str, root: object) -> LogListing | None:
    log = Path(uri) / "_delta_log"
    try:
        names = [p.name for p in log.iterdir()]
    except FileNotFoundError:
        raise TableLakeError(f"no fleet lake at {root} (no Delta table at {uri})") from None
    except OSError as exc:
        raise _damaged(root, str(exc)) from exc
    versions = []
    for name in names:
        stem, _, ext = name.partition(".")
        if stem.isdigit() and ext == "json":
            versions.append(int(stem))
        elif stem.isdigit() or name == "_last_checkpoint":
            return None  # a checkpoint, a compacted log, a CRC: delta-rs knows them
    versions.sort()
    if not versions:
        raise TableLakeError(f"no fleet lake at {root} (no Delta table at {uri})")
    if versions != list(range(len(versions))):
        missing = sorted(set(range(versions[-1] + 1)) - set(versions))
        raise _damaged(
            root, f"commit file(s) of version {', '.join(map(str, missing[:5]))} missing"
        )
    files: dict[str, dict[str, Any]] = {}
    txns: dict[str, int] = {}
    protocol = metadata = False
    for version in versions:
        name = f"{version:020d}.json"
        try:
            text = (log / name).read_text(encoding="utf-8")
        except FileNotFoundError as exc:
            raise _Vanished(f"{name}: {exc}") from exc
        except (OSError, UnicodeDecodeError) as exc:
            raise _damaged(root, f"{name}: {exc}") from exc
        for number, line in enumerate(text.splitlines(), 1):
            if not line.strip():
                continue
            try:
                action = json.loads(line)
                ((kind, body),) = action.items()
                if kind not in _ACTIONS:
                    return None
                if kind == "add":
                    if body.get("deletionVector") is not None:
                        return None
                    if type(body["size"]) is not int:
                        raise TypeError(f"size {body['size']!r}")
                    files[unquote(body["path"])] = body
                elif kind == "remove":
                    files.pop(unquote(body["path"]), None)
                elif kind == "txn":
                    txns[str(body["appId"])] = int(body["version"])
                elif kind == "protocol":
                    if int(body["minReaderVersion"]) != 1:
                        return None
                    protocol = True
                elif kind == "metaData":
                    metadata = True
            except (ValueError, TypeError, KeyError, AttributeError) as exc:
                raise _damaged(root, f"{name} line {number}: {exc!r}"[:300]) from exc
    if not (protocol and metadata):
        raise _damaged(root, "no table metadata or protocol found in the log")
    return LogListing(uri, versions[-1], files, txns)


def _damaged(root: object, why: str) -> TableLakeError:
    # Worded as LakeBase.table() words delta-rs's refusal of the same damage.
    return TableLakeError(
        f"the table's log of the fleet lake at {root} is damaged and cannot be read: {why}"
    )


__all__ = ["LogListing", "read_listing"]
