"""Where the fleet lake's files are and what their names say: object-store settings, Arrow's
file system for a remote table, content-addressed data file names (the SHA-256 of their bytes),
and the statistics the Delta log keeps of a file."""

from __future__ import annotations

import datetime as dt
import functools
import json
import os
import re
import time
import uuid
from collections.abc import Sequence
from typing import Any, Final

import pyarrow as pa
import pyarrow.compute as pc

from .schema import DataFile

#: A data file the lake writes is named after the SHA-256 of its bytes (content-addressed):
#: ``type=<kind>/part-<token>-<64 hex>.zstd.parquet``. Files written by code before this, which
#: let delta-rs compact and replace, have no hash in their name ("unhashed"); ``lake compact``
#: rewrites them.
_HASHED_NAME: Final = re.compile(r"-([0-9a-f]{64})\.zstd\.parquet$")
#: How long an object-store request may go without an answer before it is tried again, and how
#: often (Arrow's S3 client; delta-rs gets the same time-out).
S3_REQUEST_TIMEOUT_S: Final = 120.0
S3_CONNECT_TIMEOUT_S: Final = 30.0
S3_ATTEMPTS: Final = 10

#: Events read from a log at a time by the streaming commit (a chunk of 16 Ki synthetic events
#: costs ~46 MB while it is turned into tables; benchmarks/lake_add_memory.py).
CHUNK_EVENTS: Final = 1 << 13


def storage_options() -> dict[str, str]:
    """Object-store settings from the standard environment: ``AWS_ENDPOINT_URL`` (e.g. a local
    S3 server), ``AWS_ACCESS_KEY_ID``, ``AWS_SECRET_ACCESS_KEY``, ``AWS_REGION`` — read by
    delta-rs itself; only what it cannot infer is added (plain HTTP for an ``http://``
    endpoint), and time-outs as long as Arrow's client gets."""
    options = {
        "timeout": f"{S3_REQUEST_TIMEOUT_S:.0f}s",
        "connect_timeout": f"{S3_CONNECT_TIMEOUT_S:.0f}s",
    }
    if os.environ.get("AWS_ENDPOINT_URL", "").startswith("http://"):
        options["AWS_ALLOW_HTTP"] = "true"
    return options


def _filesystem(uri: str) -> tuple[Any, str]:
    """Arrow's file system for a remote table URI and the path in it (S3: the standard AWS_*
    variables, ``AWS_ENDPOINT_URL`` included); one per URI and settings (making one costs a
    round of the SDK's credential lookup)."""
    keys = ("AWS_ENDPOINT_URL", "AWS_REGION", "AWS_DEFAULT_REGION", "AWS_ACCESS_KEY_ID")
    return _filesystem_for(uri, tuple(os.environ.get(k, "") for k in keys))


@functools.cache
def _filesystem_for(uri: str, settings: tuple[str, ...]) -> tuple[Any, str]:
    import pyarrow.fs as pafs

    endpoint = settings[0] or None
    if uri.startswith("s3://"):
        fs = pafs.S3FileSystem(
            endpoint_override=endpoint,
            scheme="http" if endpoint and endpoint.startswith("http://") else "https",
            region=os.environ.get("AWS_REGION", os.environ.get("AWS_DEFAULT_REGION", "us-east-1")),
            # The SDK's defaults (3 s without a byte, 3 attempts) fail a writer whose server
            # stalls for seconds — a loaded one does (the S3 writers' test failed so once).
            request_timeout=S3_REQUEST_TIMEOUT_S,
            connect_timeout=S3_CONNECT_TIMEOUT_S,
            retry_strategy=pafs.AwsStandardS3RetryStrategy(max_attempts=S3_ATTEMPTS),
        )
        return fs, uri.removeprefix("s3://")
    fs, path = pafs.FileSystem.from_uri(uri)
    return fs, path


def _stats(part: pa.Table) -> str:
    """A data file's statistics as the Delta log keeps them: rows, and min / max of the run
    columns and of ``seq`` and ``time_ns`` (file pruning by robot, run or time)."""
    low: dict[str, Any] = {}
    high: dict[str, Any] = {}
    nulls: dict[str, int] = {}
    for name in ("robot", "date", "run", "commit", "seq", "time_ns"):
        if name not in part.column_names:
            continue
        column = part.column(name)
        nulls[name] = column.null_count
        if column.null_count == len(column):
            continue
        bounds = pc.min_max(column)
        lo, hi = bounds["min"].as_py(), bounds["max"].as_py()
        low[name] = lo.isoformat() if isinstance(lo, dt.date) else lo
        high[name] = hi.isoformat() if isinstance(hi, dt.date) else hi
    return json.dumps(
        {"numRecords": part.num_rows, "minValues": low, "maxValues": high, "nullCount": nulls}
    )


def file_sha256(path: str) -> str | None:
    """The SHA-256 a data file's name records (hex), or None for an unhashed file."""
    found = _HASHED_NAME.search(path.rpartition("/")[2])
    return found.group(1) if found else None


def _hash_mismatch(f: DataFile, actual: str) -> str | None:
    """Why a data file whose bytes hash to ``actual`` is not the file written, or None."""
    expected = file_sha256(f.path)
    if expected is None or actual == expected:
        return None
    return (
        f"{f.path}: its bytes are not the ones written (SHA-256 {actual[:16]}…, its name "
        f"records {expected[:16]}…): changed after the commit"
    )


def _hashed_name(kind: str, token: str, sha256: str) -> str:
    return f"type={kind}/part-{token}-{sha256}.zstd.parquet"


def _token() -> str:
    return f"{time.time_ns():x}-{uuid.uuid4().hex}"


def _merge(stats: Sequence[str]) -> str:
    """The statistics of a file written in parts (min of mins, max of maxes, sums)."""
    docs = [json.loads(s) for s in stats]
    low: dict[str, Any] = {}
    high: dict[str, Any] = {}
    nulls: dict[str, int] = {}
    for doc in docs:
        for k, v in doc["minValues"].items():
            low[k] = v if k not in low else min(low[k], v)
        for k, v in doc["maxValues"].items():
            high[k] = v if k not in high else max(high[k], v)
        for k, v in doc["nullCount"].items():
            nulls[k] = nulls.get(k, 0) + v
    rows = sum(d["numRecords"] for d in docs)
    return json.dumps({"numRecords": rows, "minValues": low, "maxValues": high, "nullCount": nulls})
