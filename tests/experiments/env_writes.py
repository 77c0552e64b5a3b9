"""What a command writes to the process's environment while it runs: an audit hook
(``os.putenv``, ``os.unsetenv``) sees every set and unset of a variable, ``os.environ``'s
included, so a test can check that a data folder was handed down, not set as a variable."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager

#: The names of the variables set or unset while recording (None: not recording).
_WRITES: list[str] | None = None
_HOOKED = False


def _record(event: str, args: tuple[object, ...]) -> None:
    if _WRITES is not None and event in ("os.putenv", "os.unsetenv"):
        name = args[0]
        _WRITES.append(os.fsdecode(name) if isinstance(name, (str, bytes)) else repr(name))


@contextmanager
def env_writes() -> Iterator[list[str]]:
    """The names of the variables set or unset inside the block, in order (filled as it runs)."""
    global _WRITES, _HOOKED
    if not _HOOKED:
        sys.addaudithook(_record)  # an audit hook stays for the process; it records only here
        _HOOKED = True
    writes: list[str] = []
    _WRITES = writes
    try:
        yield writes
    finally:
        _WRITES = None
