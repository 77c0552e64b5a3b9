"""The writer's seal check on its own thread: what it cannot read is damage; a bug is not."""

from __future__ import annotations

from pathlib import Path

import pytest

from objsearch.agent.catalogue import STORE
from objsearch.events import CorruptLogError, EventLog, log_seal_check

STREAM = "run-1"


def _sealed_log(directory: Path) -> bytes:
    with EventLog.open(directory, STREAM, store=STORE) as log:
        for i in range(5):
            log.append("search_failed", {"reason": f"r{i}"}, time_ns=i)
    return (directory / "events.log").read_bytes()


def _check_raises(monkeypatch: pytest.MonkeyPatch, error: Exception) -> None:
    """The check meets ``error`` (a file that cannot be read, or a bug in the check itself)."""

    def check(*args: object) -> None:
        raise error

    monkeypatch.setattr(log_seal_check, "_check_sealed", check)


def test_a_log_whose_seals_cannot_be_read_is_refused_as_damaged(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    before = _sealed_log(tmp_path)
    _check_raises(monkeypatch, OSError(5, "Input/output error"))
    log = EventLog.open(tmp_path, STREAM, verify="sealed", store=STORE)
    with pytest.raises(CorruptLogError, match="its seals could not be checked"):
        log.append("search_failed", {"reason": "on top"}, time_ns=9)
    log.close()
    assert (tmp_path / "events.log").read_bytes() == before


def test_a_bug_in_the_seal_check_reaches_the_caller_as_itself(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Not passed off as damage to the log (which says "the log was not changed" and sends the
    user to `log repair`), and never appended on."""
    before = _sealed_log(tmp_path)
    _check_raises(monkeypatch, TypeError("a bug in the check"))
    log = EventLog.open(tmp_path, STREAM, verify="sealed", store=STORE)
    with pytest.raises(TypeError, match="a bug in the check"):
        log.append("search_failed", {"reason": "on top"}, time_ns=9)
    with pytest.raises(TypeError):
        log.close()
    assert (tmp_path / "events.log").read_bytes() == before
